// Bodies that move (issue #31): the resident steps with bodies crossing the slabs' cuts, migrating to
// their new owners at rebuilds, the ghost set rebuilt and the slabs rebalanced. At every step and
// every rank count the contacts (every field's bits, by contacts_hash) equal a one-rank detection from
// scratch of the moved bodies (Engine::detect over every body: no slab, no halo, no kept list); the
// last step's contacts are the run's result. A caller's per-body state travels with its body; a
// centre that is not finite stops every rank with an InputError naming the body and the step.
//
// Every test is collective; comparisons happen on rank 0 after the last collective.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "io/scene_file.hpp"
#include "mpi/mpi_test_env.hpp"
#include "resident_steps.hpp"
#include "run/pipeline.hpp"
#include "scene/generate.hpp"
#include "support/contacts_equal.hpp"

namespace cg {
namespace {

using test::compare_contacts;
using testing::session;
using testing::write_shared;

Scene generated(const std::string& kind, std::size_t n, std::uint64_t seed) {
  GenerateOptions g;
  g.kind = kind;
  g.count = n;
  g.seed = seed;
  g.radius_low = 0.3;
  g.radius_high = 0.6;
  g.contacts_per_body = 1.0;
  g.ellipsoid_fraction = 0.4;
  return generate_scene(g);
}

// The oracle: every body of the scene at step `step` of `motion` on one engine, from scratch.
template <class Real>
Contacts<Real> from_scratch(const Scene& scene, const EngineOptions& options, const StepMotion& motion,
                            int step) {
  const bool shapes = scene.ellipsoid_count() > 0;
  BodyRows rows = body_rows(Scene(scene), shapes);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const auto id = static_cast<std::int64_t>(i);
    rows.position[i] = drifted_position(id, rows.position[i], motion.drift, step);
    if (shapes && rows.shape[i] == Shape::ellipsoid)
      rows.orientation[i] = spun_orientation(id, rows.orientation[i], motion.spin * step);
  }
  EngineOptions o = options;
  o.backend = Backend::cpu;  // the CUDA runs too are checked against the CPU's bits
  o.skin = 0;
  o.skin_auto = false;
  return Engine<Real>(o).detect(
      BodiesView{rows.position, rows.radius, {}, {}, rows.shape, rows.semi_axes, rows.orientation});
}

struct Case {
  double skin;
  bool automatic;
  SceneRead read;
  double layout_skins = 2;  // StepMotion::layout_skins
};

// Every step's contacts (hash of every field) and the last step's rows equal the one-rank detection
// from scratch of the drifted (and turned) bodies, for fixed skins, no skin and the automatic one.
template <class Real>
void check_drifting(const std::string& name, const Scene& scene, double drift, double spin,
                    Backend backend = Backend::cpu) {
  const std::string path = write_shared(name, scene);
  // skin 1: lists (and the ghost set) kept over 7 steps, while pairs close by up to 1 across the cuts;
  // skin 0.25: a layout every two of the engines' skins (the default), their builds in between, and
  // every three
  for (const Case& c : {Case{0, false, SceneRead::own_rows}, Case{0.25, false, SceneRead::all_rows},
                        Case{0.25, false, SceneRead::own_rows, 3}, Case{1.0, false, SceneRead::own_rows, 1},
                        Case{0, true, SceneRead::own_rows}}) {
    DistributedOptions o;
    o.engine.backend = backend;
    o.engine.threads = 1;
    o.engine.fields = Fields::full;
    o.engine.skin = c.skin;
    o.engine.skin_auto = c.automatic;
    o.read = c.read;
    o.resident_steps = 9;
    o.step_motion.drift = drift;
    o.step_motion.spin = spin;
    o.step_motion.hash_every_step = true;
    o.step_motion.layout_skins = c.layout_skins;
    const std::string label = name + (backend == Backend::cuda ? " cuda" : " cpu") +
                              (std::is_same_v<Real, float> ? " fp32" : " fp64") + ", skin " +
                              (c.automatic ? std::string("auto") : std::to_string(c.skin)) + " (layouts of " +
                              std::to_string(c.layout_skins) + " skins) at " +
                              std::to_string(session().size()) + " rank(s)";
    const DistributedResult<Real> got = distributed_detect<Real>(session(), path, o);
    const StepStats& st = got.steps;
    ASSERT_EQ(st.steps, 9) << label;
    ASSERT_EQ(st.step_hashes.size(), 9u) << label;
    EXPECT_EQ(st.skin_auto, c.automatic) << label;
    if (session().size() > 1) {
      EXPECT_GT(st.migrated, 0u) << label << ": no body changed rank";
      EXPECT_GT(st.rebuilds, 0u) << label;
    }
    if (c.skin > 0) {
      EXPECT_GT(st.reuses, 0u) << label;
    }
    if (session().size() > 1 && c.skin > 0 && c.layout_skins > 1) {  // builds between the layouts
      EXPECT_GT(st.builds, st.rebuilds + 1) << label;
    }
    if (session().rank() != 0) continue;
    for (int step = 1; step <= 9; ++step) {
      const Contacts<Real> want = from_scratch<Real>(scene, o.engine, o.step_motion, step);
      EXPECT_EQ(st.step_contacts[static_cast<std::size_t>(step - 1)], want.size())
          << label << ", step " << step;
      EXPECT_EQ(st.step_hashes[static_cast<std::size_t>(step - 1)], contacts_hash(want))
          << label << ", step " << step;
      if (step == 9) {
        EXPECT_EQ(got.contacts.size(), want.size()) << label;
        EXPECT_EQ(compare_contacts(got.contacts, want), "identical") << label << ": the last step's rows";
        EXPECT_EQ(got.total_contacts, want.size()) << label;
        EXPECT_NE(contacts_hash(want), contacts_hash(from_scratch<Real>(scene, o.engine, o.step_motion, 0)))
            << label << ": the drift must change the contacts";
      }
    }
  }
}

TEST(MovingSteps, DriftingSpheresEqualOneRankFromScratchEveryStep) {
  const Scene scene = generated("uniform", 2500, 61);
  check_drifting<double>("drift_spheres", scene, 0.07, 0);
  check_drifting<float>("drift_spheres", scene, 0.07, 0);
}

TEST(MovingSteps, DriftingTurningEllipsoidsEqualOneRankFromScratchEveryStep) {
  check_drifting<double>("drift_mixed", generated("mixed", 1500, 62), 0.07, 0.2);
}

// Mixed sizes crossing the cuts (detect's steps halo by radius: a large body goes to every slab it
// reaches, a small one only as far as small partners need it, a pair of a large and a small body is
// reported by the small one's owner): six intruders of radius 3 among grains of 0.3, and a bimodal
// 1:5 mix, drifting across the cuts.
Scene two_sizes(const std::string& kind, std::uint64_t seed, double r_high) {
  GenerateOptions g;
  g.kind = kind;
  g.count = 2500;
  g.seed = seed;
  g.radius_low = 0.3;
  g.radius_high = r_high;
  g.contacts_per_body = 1.0;
  g.intruders = 6;
  g.large_fraction = 0.5;
  return generate_scene(g);
}

TEST(MovingSteps, MixedSizesCrossingTheCutsEqualOneRankFromScratchEveryStep) {
  check_drifting<double>("drift_intruders", two_sizes("intruders", 63, 3.0), 0.07, 0);
  check_drifting<float>("drift_bimodal", two_sizes("bimodal", 64, 1.5), 0.07, 0);
}

TEST(MovingSteps, CudaMixedSizesCrossingTheCutsEqualTheCpuFromScratchEveryStep) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  check_drifting<double>("drift_intruders", two_sizes("intruders", 63, 3.0), 0.07, 0, Backend::cuda);
  check_drifting<float>("drift_bimodal", two_sizes("bimodal", 64, 1.5), 0.07, 0, Backend::cuda);
}

// The same steps on the GPU (device-resident engines, host-staged halo and migration): every step's
// bits equal the CPU's one-rank detection from scratch.
TEST(MovingSteps, CudaDriftingBodiesEqualTheCpuFromScratchEveryStep) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  const Scene spheres = generated("uniform", 2500, 61);
  check_drifting<double>("drift_spheres", spheres, 0.07, 0, Backend::cuda);
  check_drifting<float>("drift_spheres", spheres, 0.07, 0, Backend::cuda);
  check_drifting<double>("drift_mixed", generated("mixed", 1500, 62), 0.07, 0.2, Backend::cuda);
}

// ---- the loop as a library: a caller's integrator, its per-body state, the slabs rebalanced -------

struct Velocity {
  Vec3<double> v;
};

// n bodies in [0, 30)³, radii 0.3 … 0.6; body i's velocity pushes the left of the box to the right
// (so the owned counts drift apart and the slabs rebalance).
struct World {
  std::vector<Vec3<double>> position;
  std::vector<double> radius;
  std::vector<Vec3<double>> velocity;
};
World world(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> x(0, 30), r(0.3, 0.6), jitter(-0.02, 0.02);
  World w;
  for (std::size_t i = 0; i < n; ++i) {
    w.position.push_back({x(rng), x(rng), x(rng)});
    w.radius.push_back(r(rng));
    w.velocity.push_back({0.2 * (1 - w.position.back().x / 30), jitter(rng), jitter(rng)});
  }
  return w;
}

// This rank's bodies of `w` for `slabs` (ascending id), each with its velocity as its state.
StepBodies owned_of(const World& w, const SlabDecomposition& slabs) {
  StepBodies b;
  b.state_bytes = sizeof(Velocity);
  for (std::size_t i = 0; i < w.position.size(); ++i) {
    if (slabs.owner(w.position[i].x) != session().rank()) continue;
    b.position.push_back(w.position[i]);
    b.radius.push_back(w.radius[i]);
    b.id.push_back(static_cast<std::int64_t>(i));
    const Velocity v{w.velocity[i]};
    const auto* bytes = reinterpret_cast<const std::byte*>(&v);
    b.state.insert(b.state.end(), bytes, bytes + sizeof(Velocity));
  }
  return b;
}

// The caller's integrator: x += v, v read from each body's state.
void integrate(StepBodies& b) {
  for (std::size_t k = 0; k < b.size(); ++k) {
    Velocity v;
    std::memcpy(&v, b.state.data() + k * sizeof(Velocity), sizeof(Velocity));
    b.position[k] = b.position[k] + v.v;
  }
}

// One step as pipeline.cpp sequences it.
void step(StepLoop<double>& loop, int s) {
  loop.update_frame(s);
  if (loop.rebuild_due()) {
    loop.rebalance();
    loop.migrate();
    loop.lay_out();
  }
  loop.commit({true, false});
  loop.detect_interior();
  loop.refresh_ghosts();
  loop.detect_boundary();
  loop.collect();
}

TEST(StepLoop, CallerStateTravelsAndTheSlabsRebalance) {
  World w = world(2500, 71);
  EngineOptions options;
  options.backend = Backend::cpu;
  options.threads = 1;
  options.fields = Fields::full;
  options.skin = 0.45;
  Engine<double> engine(options);
  const SlabDecomposition slabs = SlabDecomposition::equal_width(0, 0, 30, session().size());
  StepMotion motion;
  motion.hash_every_step = true;
  StepBalance balance;
  balance.threshold = 0.02;
  StepLoop<double> loop(session(), engine, slabs, motion, 1, balance);
  loop.bodies() = owned_of(w, slabs);
  loop.update_frame(0);
  loop.lay_out();
  const int steps = 12;
  std::vector<std::uint64_t> want;  // rank 0: the oracle's hash per step
  for (int s = 1; s <= steps; ++s) {
    integrate(loop.bodies());
    step(loop, s);
    for (std::size_t i = 0; i < w.position.size(); ++i) w.position[i] = w.position[i] + w.velocity[i];
    if (session().rank() == 0) {
      EngineOptions o = options;
      o.skin = 0;
      want.push_back(contacts_hash(Engine<double>(o).detect(BodiesView{w.position, w.radius, {}, {}})));
    }
  }
  const StepStats st = loop.stats();
  const StepBodies all = loop.gather_bodies();
  // every body's state is its own velocity, wherever it went
  bool states = true;
  const StepBodies& mine = loop.bodies();
  for (std::size_t k = 0; k < mine.size(); ++k) {
    Velocity v;
    std::memcpy(&v, mine.state.data() + k * sizeof(Velocity), sizeof(Velocity));
    const Vec3<double> u = w.velocity[static_cast<std::size_t>(mine.id[k])];
    states = states && v.v.x == u.x && v.v.y == u.y && v.v.z == u.z;
  }
  EXPECT_TRUE(states) << "a body's state did not travel with it";
  EXPECT_EQ(st.steps, steps);
  EXPECT_GT(st.reuses, 0u);
  if (session().size() > 1) {
    EXPECT_GT(st.migrated, 0u);
    EXPECT_GT(st.rebalances, 0u) << "the owned counts drifted apart, yet no rebalance";
    EXPECT_NE(loop.slabs().cuts(), slabs.cuts());
  }
  if (session().rank() != 0) return;
  ASSERT_EQ(st.step_hashes.size(), want.size());
  for (int s = 0; s < steps; ++s)
    EXPECT_EQ(st.step_hashes[static_cast<std::size_t>(s)], want[static_cast<std::size_t>(s)])
        << "step " << s + 1;
  ASSERT_EQ(all.size(), w.position.size());
  for (std::size_t i = 0; i < all.size(); ++i) {
    ASSERT_EQ(all.id[i], static_cast<std::int64_t>(i));
    ASSERT_EQ(std::memcmp(&all.position[i], &w.position[i], sizeof(Vec3<double>)), 0) << "body " << i;
  }
}

// The loop's halo by radius (StepMotion::ghosts_by_radius) against one width for all, through the
// loop's own API: eight bodies of radius 4 among 2 500 of 0.3 … 0.6 moved by the caller's integrator
// (migrations and rebuilds). Both give the oracle's contacts at every step; the halo by radius sends
// a fraction of the rows (the small bodies' widths do not follow the largest radius).
TEST(StepLoop, HaloByRadiusSendsFewerRowsAndFindsTheSameContacts) {
  World w = world(2500, 73);
  for (std::size_t i = 100; i < w.radius.size(); i += 300) w.radius[i] = 4.0;
  std::vector<std::uint64_t> want;  // rank 0: the oracle's hash per step
  std::uint64_t sent[2] = {0, 0};
  for (const bool by_radius : {false, true}) {
    World moving = w;
    EngineOptions options;
    options.backend = Backend::cpu;
    options.threads = 1;
    options.skin = 0.45;
    Engine<double> engine(options);
    const SlabDecomposition slabs = SlabDecomposition::equal_width(0, 0, 30, session().size());
    StepMotion motion;
    motion.hash_every_step = true;
    motion.ghosts_by_radius = by_radius;
    StepLoop<double> loop(session(), engine, slabs, motion, 1);
    loop.bodies() = owned_of(moving, slabs);
    loop.update_frame(0);
    loop.lay_out();
    std::uint64_t halo = loop.halo().total();
    for (int s = 1; s <= 8; ++s) {
      integrate(loop.bodies());
      step(loop, s);
      halo += loop.halo().total();
      for (std::size_t i = 0; i < moving.position.size(); ++i)
        moving.position[i] = moving.position[i] + moving.velocity[i];
      if (session().rank() == 0 && !by_radius) {
        EngineOptions o = options;
        o.skin = 0;
        want.push_back(
            contacts_hash(Engine<double>(o).detect(BodiesView{moving.position, moving.radius, {}, {}})));
      }
    }
    const StepStats st = loop.stats();
    sent[by_radius ? 1 : 0] = session().sum(halo);
    if (session().size() > 1) {
      EXPECT_GT(st.migrated, 0u);
    }
    if (session().rank() != 0) continue;
    ASSERT_EQ(st.step_hashes.size(), want.size());
    for (std::size_t s = 0; s < want.size(); ++s)
      EXPECT_EQ(st.step_hashes[s], want[s]) << (by_radius ? "by radius" : "one width") << ", step " << s + 1;
  }
  if (session().size() > 1) {
    EXPECT_LT(2 * sent[1], sent[0]) << sent[1] << " rows against " << sent[0];
  }
}

// A centre that becomes NaN during the steps stops every rank with an InputError naming the body and
// the step (never a hang, never a sweep of all pairs). After the first layout engine A finds it
// where its rows are (Engine::resident_extent; CUDA: on the device, the row named by its global id).
void check_non_finite_centre(Backend backend) {
  const World w = world(800, 72);
  EngineOptions options;
  options.backend = backend;
  options.threads = 1;
  options.skin = 0.3;
  Engine<double> engine(options);
  const SlabDecomposition slabs = SlabDecomposition::equal_width(0, 0, 30, session().size());
  StepLoop<double> loop(session(), engine, slabs, StepMotion{}, 1);
  loop.bodies() = owned_of(w, slabs);
  loop.update_frame(0);
  loop.lay_out();
  const std::int64_t bad = 417;
  try {
    for (int s = 1; s <= 3; ++s) {
      integrate(loop.bodies());
      StepBodies& b = loop.bodies();
      if (s == 2)
        for (std::size_t k = 0; k < b.size(); ++k)
          if (b.id[k] == bad) b.position[k].y = std::numeric_limits<double>::quiet_NaN();
      step(loop, s);
    }
    ADD_FAILURE() << "a NaN centre passed";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("step 2"), std::string::npos) << what;
    EXPECT_NE(what.find("body 417"), std::string::npos) << what;
  }
}

// The halo where the rows are, the slab scans of the engines and the merge beside the layout (the
// defaults) against the former paths (CONTACTGRID_STEP_HALO=host: the host's records and B's rows
// written whole; CONTACTGRID_STEP_SCAN=host: the host's pass over every row for the owners and the
// plan; CONTACTGRID_STEP_MERGE=wait: the merge before the layout): every
// step's contacts and the last step's rows the same bits, the same ghosts, and the knobs did switch.
template <class Real>
void check_former_paths(Backend backend) {
  const Scene scene = generated("mixed", 1500, 65);
  const std::string path = write_shared("former_paths", scene);
  struct Run {
    StepStats st;
    Contacts<Real> last;
  };
  // the knobs as the process got them (a job may run the whole suite under the former paths), put
  // back after each run: `now` runs the defaults, `former` the former paths, `beside` the merge beside
  // the layout with the whole share of threads each (not beside the detection)
  const char* const knobs[] = {"CONTACTGRID_STEP_HALO", "CONTACTGRID_STEP_SCAN", "CONTACTGRID_STEP_MERGE",
                               "CONTACTGRID_STEP_MERGE_TEAM"};
  std::vector<std::optional<std::string>> given;
  for (const char* k : knobs) {
    const char* v = std::getenv(k);
    given.push_back(v ? std::optional<std::string>(v) : std::nullopt);
  }
  auto restore = [&] {
    for (std::size_t i = 0; i < given.size(); ++i) {
      if (given[i])
        setenv(knobs[i], given[i]->c_str(), 1);
      else
        unsetenv(knobs[i]);
    }
  };
  enum class Paths { now, former, beside };
  auto run = [&](Paths paths) {
    for (const char* k : knobs) unsetenv(k);
    if (paths == Paths::former) {
      setenv("CONTACTGRID_STEP_HALO", "host", 1);
      setenv("CONTACTGRID_STEP_SCAN", "host", 1);
      setenv("CONTACTGRID_STEP_MERGE", "wait", 1);
    } else if (paths == Paths::beside) {
      setenv("CONTACTGRID_STEP_MERGE", "layout", 1);
      setenv("CONTACTGRID_STEP_MERGE_TEAM", "whole", 1);
    }
    DistributedOptions o;
    o.engine.backend = backend;
    o.engine.threads = 2;
    o.engine.fields = Fields::full;
    o.engine.skin = 0.25;
    o.read = SceneRead::own_rows;
    o.resident_steps = 9;
    o.step_motion.drift = 0.07;
    o.step_motion.spin = 0.2;
    o.step_motion.hash_every_step = true;
    o.step_motion.ghosts_by_radius = true;
    DistributedResult<Real> r = distributed_detect<Real>(session(), path, o);
    restore();
    return Run{r.steps, std::move(r.contacts)};
  };
  const Run now = run(Paths::now), former = run(Paths::former), beside = run(Paths::beside);
  const bool several = session().size() > 1;
  EXPECT_EQ(now.st.halo_on_device, several);  // one rank has no halo
  EXPECT_FALSE(former.st.halo_on_device);
  EXPECT_TRUE(now.st.oriented == several && former.st.oriented == several);
  EXPECT_EQ(now.st.step_hashes, former.st.step_hashes);
  EXPECT_EQ(now.st.step_contacts, former.st.step_contacts);
  EXPECT_EQ(now.st.halo_rows, former.st.halo_rows);
  EXPECT_EQ(now.st.migrated, former.st.migrated);
  EXPECT_EQ(now.st.rebuilds, former.st.rebuilds);
  EXPECT_EQ(now.st.step_hashes, beside.st.step_hashes);
  EXPECT_EQ(now.st.migrated, beside.st.migrated);
  if (several) {
    EXPECT_GT(now.st.migrated, 0u);
    EXPECT_GT(now.st.halo_rows, 0u);
  }
  if (session().rank() == 0) {
    EXPECT_EQ(compare_contacts(now.last, former.last), "identical");
    EXPECT_EQ(compare_contacts(now.last, beside.last), "identical");
  }
}

TEST(MovingSteps, TheHaloAndScansWhereTheRowsAreGiveTheFormerPathsBits) {
  check_former_paths<double>(Backend::cpu);
  check_former_paths<float>(Backend::cpu);
}

TEST(MovingSteps, CudaTheHaloAndScansWhereTheRowsAreGiveTheFormerPathsBits) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  check_former_paths<double>(Backend::cuda);
  check_former_paths<float>(Backend::cuda);
}

// A layout of fewer than one skin (StepMotion::layout_skins) would let bodies leave the ghost set
// between layouts: refused on every rank before any step.
TEST(StepLoop, ALayoutOfFewerThanOneSkinIsRefused) {
  const std::string path = write_shared("layout_skins", generated("uniform", 400, 65));
  for (const double k : {0.5, 0.0, -1.0, std::numeric_limits<double>::quiet_NaN()}) {
    DistributedOptions o;
    o.engine.threads = 1;
    o.engine.skin = 0.25;
    o.resident_steps = 2;
    o.step_motion.drift = 0.07;
    o.step_motion.layout_skins = k;
    EXPECT_THROW(distributed_detect<double>(session(), path, o), UsageError) << "layout_skins " << k;
  }
}

TEST(StepLoop, NonFiniteCentreNamesBodyAndStep) { check_non_finite_centre(Backend::cpu); }

TEST(StepLoop, NonFiniteCentreNamesBodyAndStepOnCuda) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  check_non_finite_centre(Backend::cuda);
}

}  // namespace
}  // namespace cg
