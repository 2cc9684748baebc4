// The resident steps with turning ellipsoids (issue #12): each step turns every ellipsoid by the
// spin's rule on its owner, the ghosts' orientations travel through the halo, and the last step's
// contacts must equal a one-rank detection from scratch of the whole scene turned by the same rule
// (rank 0, Engine::detect over every body: no slab, no halo, no resident rows). A variant whose
// ghosts keep their first orientations must be caught by the run's own check.
//
// Every test is collective; comparisons happen on rank 0 after the last collective.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>

#include "io/scene_file.hpp"
#include "mpi/mpi_test_env.hpp"
#include "run/distributed_detect.hpp"
#include "scene/generate.hpp"

namespace cg {
namespace {

using testing::session;
using testing::write_shared;

// 40 % ellipsoids (aspect up to 1/0.3), about one contact per body: many pairs with an ellipsoid
// cross every cut, so a turn of 0.9 rad changes contacts there.
Scene mixed_scene(std::uint64_t seed) {
  GenerateOptions g;
  g.kind = "mixed";
  g.count = 4000;
  g.seed = seed;
  g.radius_low = 0.3;
  g.radius_high = 1.0;
  g.contacts_per_body = 1.0;
  g.ellipsoid_fraction = 0.4;
  return generate_scene(g);
}

struct PairSet {
  std::uint64_t contacts = 0, hash = 0;
  bool operator==(const PairSet&) const = default;
};

template <class Real>
PairSet pair_set(const Contacts<Real>& c) {
  PairSet s{c.size(), 0};
  for (std::size_t k = 0; k < c.size(); ++k)
    s.hash += pair_hash(std::min(c.id_a[k], c.id_b[k]), std::max(c.id_a[k], c.id_b[k]));
  return s;
}

// The oracle: every body of the scene on one engine, each ellipsoid turned by `angle` (ids: spheres
// 0 … N-1, then the ellipsoids).
PairSet one_rank_turned(const Scene& scene, const EngineOptions& options, double angle) {
  BodyRows rows = body_rows(Scene(scene), true);
  for (std::size_t i = 0; i < rows.size(); ++i)
    if (rows.shape[i] == Shape::ellipsoid)
      rows.orientation[i] = spun_orientation(static_cast<std::int64_t>(i), rows.orientation[i], angle);
  Engine<double> engine(options);
  return pair_set(engine.detect(
      BodiesView{rows.position, rows.radius, {}, {}, rows.shape, rows.semi_axes, rows.orientation}));
}

DistributedOptions turning_options(SceneRead read, double skin = 0) {
  DistributedOptions o;
  o.engine.backend = Backend::cpu;
  o.engine.threads = 1;  // the test machines are shared: one thread per rank
  o.engine.skin = skin;
  o.read = read;
  o.resident_steps = 3;
  o.step_motion.spin = 0.3;
  return o;
}

// With the ghosts' orientations refreshed every step, the last step's pairs are the turned scene's,
// at every rank count, own rows (redistributed bodies) or every row, with or without a skin, and with
// the semi-axes travelling too (StepMotion::send_semi_axes). The turn changes the contacts, so a
// step that kept the file's orientations anywhere could not pass.
TEST(ResidentSteps, TurningEllipsoidsEqualOneRankFromScratch) {
  const Scene scene = mixed_scene(31);
  const std::string path = write_shared("turning", scene);
  struct Case {
    SceneRead read;
    double skin;
    bool semi_axes;
    const char* what;
  };
  for (const Case& c : {Case{SceneRead::own_rows, 0, false, "own rows"},
                        Case{SceneRead::all_rows, 0.05, false, "every row, skin 0.05"},
                        Case{SceneRead::own_rows, 0, true, "own rows, semi-axes sent"}}) {
    DistributedOptions o = turning_options(c.read, c.skin);
    o.step_motion.send_semi_axes = c.semi_axes;
    const std::string label = std::string(c.what) + " at " + std::to_string(session().size()) + " rank(s)";
    const DistributedResult<double> got = distributed_detect<double>(session(), path, o);
    EXPECT_EQ(got.steps.steps, 3) << label;
    EXPECT_TRUE(got.steps.turned) << label;
    EXPECT_EQ(got.steps.spin, 0.3) << label;
    if (session().rank() != 0) continue;
    const PairSet turned = one_rank_turned(scene, o.engine, 0.3 * 3);
    EXPECT_EQ((PairSet{got.steps.contacts, got.steps.hash}), turned)
        << label << ": " << got.steps.contacts << " contacts, one rank from scratch " << turned.contacts;
    EXPECT_NE(pair_set(got.contacts), turned) << label << ": the turn must change the contacts";
    EXPECT_GT(got.contacts.size(), 1000u) << label;
  }
}

// The ghosts keeping their first orientations (B's shape rows never refreshed) is what the refresh
// prevents: with more than one rank the run's own check fails, on every rank, naming the stale
// orientation; one rank has no ghosts and passes.
TEST(ResidentSteps, StaleGhostOrientationsAreCaught) {
  const std::string path = write_shared("stale", mixed_scene(32));
  DistributedOptions o = turning_options(SceneRead::own_rows);
  o.step_motion.refresh_shapes = false;
  if (session().size() == 1) {
    EXPECT_NO_THROW(distributed_detect<double>(session(), path, o));
    return;
  }
  try {
    distributed_detect<double>(session(), path, o);
    ADD_FAILURE() << "stale ghost orientations passed the check at " << session().size() << " ranks";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("stale orientation"), std::string::npos) << e.what();
  }
}

// A spin on a sphere-only scene turns nothing: the steps are today's (the file's contacts every step,
// checked inside), with nothing more sent.
TEST(ResidentSteps, SpinOnSpheresChangesNothing) {
  GenerateOptions g;
  g.count = 3000;
  g.seed = 33;
  const std::string path = write_shared("spin_spheres", generate_scene(g));
  DistributedOptions o = turning_options(SceneRead::own_rows);
  const DistributedResult<double> got = distributed_detect<double>(session(), path, o);
  EXPECT_FALSE(got.steps.turned);
  EXPECT_EQ(got.steps.contacts, got.total_contacts);
  if (session().rank() == 0) {
    EXPECT_EQ((PairSet{got.steps.contacts, got.steps.hash}), pair_set(got.contacts));
  }
}

}  // namespace
}  // namespace cg
