// End-to-end tests of the MPI slab decomposition (comm/distributed_detect): on every scene, at every
// rank count, the distributed result must equal the single-rank Engine::detect on the whole scene
// exactly: every field bit for bit, in the same order, in fp64 and fp32.
//
// Every test is collective: all ranks run it; comparisons happen on rank 0 after the last collective
// (so a failed assertion never leaves a rank behind in a collective).
#include "run/distributed_detect.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "mpi/mpi_test_env.hpp"
#include "scene/generate.hpp"
#include "support/contacts_equal.hpp"

namespace cg {
namespace {

using test::compare_contacts;
using testing::session;
using testing::write_shared;

// ---- scenes (seeded, fresh per test) -----------------------------------------------------------------

Scene random_scene(std::uint64_t seed, std::size_t n, Vec3<double> lo, Vec3<double> hi, double r_low,
                   double r_high, bool log_radius = false) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> ux(lo.x, hi.x), uy(lo.y, hi.y), uz(lo.z, hi.z), u01(0, 1);
  Scene s;
  for (std::size_t i = 0; i < n; ++i) {
    s.sphere_position.push_back({ux(rng), uy(rng), uz(rng)});
    const double t = u01(rng);
    s.sphere_radius.push_back(log_radius ? r_low * std::pow(r_high / r_low, t)
                                         : r_low + t * (r_high - r_low));
  }
  return s;
}

// Edge of a cube holding n spheres of mean radius r with about 0.4 contacts per body.
double box_edge(std::size_t n, double r) {
  return std::cbrt(static_cast<double>(n) * (4.0 / 3.0) * std::numbers::pi * std::pow(2 * r, 3) / 0.8);
}

Scene uniform_scene(std::uint64_t seed, std::size_t n) {
  const double l = box_edge(n, 0.75);
  return random_scene(seed, n, {0, 0, 0}, {l, l, l}, 0.5, 1.0);
}

// Radii spanning a factor 40 (log-uniform): r_max sets the ghost width, most bodies are far smaller.
Scene polydisperse_scene(std::uint64_t seed, std::size_t n) {
  const double l = box_edge(n, 0.4);
  return random_scene(seed, n, {-l, 0, 0}, {0, l, l / 2}, 0.05, 2.0, true);
}

// A pile: every body in the bottom tenth of a tall box (z), far from the origin.
Scene pile_scene(std::uint64_t seed, std::size_t n) {
  const double l = box_edge(n, 0.75);
  Scene s = random_scene(seed, n, {1000, 1000, 1000}, {1000 + 2 * l, 1000 + 2 * l, 1000 + l / 4}, 0.5, 1.0);
  s.sphere_position.push_back({1000, 1000, 1000 + 10 * l});  // the top of the box: one lone body
  s.sphere_radius.push_back(0.75);
  return s;
}

// A lattice of touching spheres (spacing exactly 2r = 2·r_max = the exact ghost width, so
// d == ra + rb: touching counts), many bodies sharing each coordinate: quantile cuts fall exactly on
// bodies' centres, many bodies lie exactly on cuts. Plus coincident centres (normal (1, 0, 0)).
// `mirrored`: ids decrease along every axis, so the smaller id of a pair across a cut is the body ON
// the cut (upper slab) and its partner lies a full 2·r_max below: it must reach it as a ghost.
Scene lattice_scene(std::uint64_t seed, int side, bool mirrored) {
  std::mt19937_64 rng(seed);
  Scene s;
  for (int i = 0; i < side; ++i) {
    for (int j = 0; j < side; ++j) {
      for (int k = 0; k < side; ++k) {
        if (rng() % 7 == 0) continue;  // holes, so ids do not follow the lattice
        const int m = side - 1;
        s.sphere_position.push_back(mirrored ? Vec3<double>{1.0 * (m - i), 1.0 * (m - j), 1.0 * (m - k)}
                                             : Vec3<double>{1.0 * i, 1.0 * j, 1.0 * k});
        s.sphere_radius.push_back(0.5);
      }
    }
  }
  for (int c = 0; c < 5; ++c) {
    Vec3<double> p = s.sphere_position[rng() % s.sphere_position.size()];
    s.sphere_position.push_back(p);
    s.sphere_radius.push_back(0.25);
  }
  return s;
}

// All centres share one x: along x every body is in one slab, the others are empty.
Scene one_plane_scene(std::uint64_t seed, std::size_t n) {
  const double l = box_edge(n, 0.75) * 1.5;
  return random_scene(seed, n, {3.0, 0, 0}, {3.0, l, l}, 0.5, 1.0);
}

// Width along x about two ghost widths (r_max = 1 -> w ~ 2): with 4 ranks every slab is thinner than
// the ghost width, so ghosts go beyond the neighbours.
Scene thin_scene(std::uint64_t seed, std::size_t n) {
  const double l = std::sqrt(static_cast<double>(n) * 4.0 / 0.8 / 4.0) * 1.2;
  return random_scene(seed, n, {0, 0, 0}, {4.0, l, l}, 0.5, 1.0);
}

// ---- checks ----------------------------------------------------------------------------------------

template <class Real>
void expect_identical(const Contacts<Real>& got, const Contacts<Real>& want, const std::string& what) {
  EXPECT_EQ(got.size(), want.size()) << what;
  EXPECT_EQ(got.full, want.full) << what;
  EXPECT_EQ(compare_contacts(got, want), "identical") << what;
}

DistributedOptions base_options(Fields fields = Fields::full) {
  DistributedOptions o;
  o.engine.backend = Backend::cpu;
  o.engine.fields = fields;
  o.engine.threads = 1;  // the test machines are shared: one thread per rank
  return o;
}

// The distributed run equals the single-rank engine on the whole scene, bit for bit.
template <class Real>
std::size_t check_equal_to_single_rank(const std::string& path, const Scene& scene,
                                       const DistributedOptions& options, const std::string& what) {
  DistributedResult<Real> got = distributed_detect<Real>(session(), path, options);
  const std::string label = what + (std::is_same_v<Real, float> ? " fp32" : " fp64") + " at " +
                            std::to_string(session().size()) + " rank(s)";
  EXPECT_EQ(got.bodies, scene.size()) << label;
  EXPECT_EQ(got.ranks, session().size()) << label;
  if (session().size() > 1) {  // automatic: every row, since the test ranks share one node
    EXPECT_EQ(got.read, options.read == SceneRead::automatic ? SceneRead::all_rows : options.read) << label;
  }
  EXPECT_EQ(got.cuts.size(), static_cast<std::size_t>(session().size() - 1)) << label;
  // resident steps: every step found the run's contacts (counted, and on the CPU backend the pairs
  // themselves, by an order-free hash; a difference throws inside the run)
  EXPECT_EQ(got.steps.steps, options.resident_steps) << label;
  if (options.resident_steps > 0) {
    EXPECT_EQ(got.steps.contacts, got.total_contacts) << label;
  }
  {  // the six top-level stages in order, then (inside "detect") the engine's own stages
    std::vector<std::string> top;
    for (const auto& t : got.times)
      if (t.engine_stage < 0) top.push_back(t.name());
    EXPECT_EQ(top, (std::vector<std::string>{"read", "redistribute", "halo", "detect", "gather", "merge"}))
        << label;
  }
  if (session().rank() != 0) {
    EXPECT_EQ(got.contacts.size(), 0u) << label << ": contacts on a rank other than 0";
    return 0;
  }
  EXPECT_EQ(got.duplicates_removed, 0u) << label;
  Engine<Real> engine(options.engine);
  const Contacts<Real> want = engine.detect(BodiesView{scene.sphere_position, scene.sphere_radius, {}, {}});
  EXPECT_EQ(
      got.cell_size,
      make_frame(compute_bounds(BodiesView{scene.sphere_position, scene.sphere_radius, {}, {}}),
                 options.engine.cell_size, std::is_same_v<Real, float> ? Precision::fp32 : Precision::fp64)
          .cell_size)
      << label;
  expect_identical(got.contacts, want, label);
  return want.size();
}

// Both precisions, and both read modes: own rows + redistribution + halo, and every row + selection;
// then two resident steps (with own rows: the halo layout from redistributed bodies).
std::size_t check_both_precisions(const std::string& name, const Scene& scene,
                                  const DistributedOptions& options = base_options()) {
  const std::string path = write_shared(name, scene);
  std::size_t k = 0;
  for (SceneRead read : {SceneRead::own_rows, SceneRead::all_rows}) {
    DistributedOptions o = options;
    o.read = read;
    o.resident_steps = read == SceneRead::own_rows ? 2 : 1;
    const std::string what = name + (read == SceneRead::own_rows ? " (own rows)" : " (every row)");
    k = check_equal_to_single_rank<double>(path, scene, o, what);
    check_equal_to_single_rank<float>(path, scene, o, what);
  }
  return k;
}

// ---- the scenes ------------------------------------------------------------------------------------

TEST(DistributedDetect, UniformEqualsSingleRank) {
  const std::size_t k = check_both_precisions("uniform", uniform_scene(101, 2000));
  if (session().rank() == 0) {
    EXPECT_GT(k, 200u);  // the scene has contacts to compare
  }
}

TEST(DistributedDetect, UniformBasicFieldsEqualsSingleRank) {
  check_both_precisions("uniform_basic", uniform_scene(102, 1500), base_options(Fields::basic));
}

TEST(DistributedDetect, PolydisperseEqualsSingleRank) {
  const std::size_t k = check_both_precisions("polydisperse", polydisperse_scene(103, 2000));
  if (session().rank() == 0) {
    EXPECT_GT(k, 50u);
  }
}

TEST(DistributedDetect, PileInTheBottomTenthEqualsSingleRank) {
  check_both_precisions("pile", pile_scene(104, 1500));
  DistributedOptions along_z = base_options();
  along_z.axis = SlabAxis::z;  // slabs across the pile: the top slabs hold almost nothing
  check_both_precisions("pile_z", pile_scene(105, 1500), along_z);
  DistributedOptions width_z = along_z;
  width_z.balance = Balance::width;  // equal widths: the pile is all in the first slab
  check_both_precisions("pile_z_width", pile_scene(106, 1500), width_z);
}

TEST(DistributedDetect, BodiesExactlyOnSlabBoundariesEqualsSingleRank) {
  for (bool mirrored : {false, true}) {
    for (int axis : {-1, 0, 2}) {
      DistributedOptions o = base_options();
      o.axis = static_cast<SlabAxis>(axis);
      const std::string name = std::string(mirrored ? "mirrored_" : "lattice_") + std::to_string(axis);
      const std::size_t k = check_both_precisions(name, lattice_scene(107, 9, mirrored), o);
      if (session().rank() == 0) {
        EXPECT_GT(k, 1000u);
      }
    }
  }
}

// Far from the frame origin, fp32 local coordinates round to ~1e-3: pairs whose exact centre distance
// 1.0002 exceeds ra + rb = 1 = 2·r_max touch in fp32. The ghost width's rounding margin must cover
// them (the body with the smaller id is the upper one, so the lower one must come as a ghost).
Scene rounding_scene() {
  Scene s;
  s.sphere_position.push_back({-1.0e4, 0, 0});  // puts the frame origin far away
  s.sphere_radius.push_back(0.5);
  for (int k = 0; k < 300; ++k) {
    const double x = 10.0 * k + 0.37 * (k % 7);
    s.sphere_position.push_back({x + 1.0002, 0, 0});
    s.sphere_radius.push_back(0.5);
    s.sphere_position.push_back({x, 0, 0});
    s.sphere_radius.push_back(0.5);
  }
  return s;
}

TEST(DistributedDetect, Fp32RoundingAcrossCutsEqualsSingleRank) {
  const Scene scene = rounding_scene();
  const std::string path = write_shared("rounding", scene);
  check_equal_to_single_rank<double>(path, scene, base_options(), "rounding");
  const std::size_t k = check_equal_to_single_rank<float>(path, scene, base_options(), "rounding");
  if (session().rank() == 0) {
    EXPECT_GT(k, 100u);  // the fp32 run does see these pairs in contact
  }
}

TEST(DistributedDetect, AllBodiesInOneSlabEqualsSingleRank) {
  DistributedOptions o = base_options();
  o.axis = SlabAxis::x;  // every centre at x = 3: one slab owns everything, the others are empty
  check_both_precisions("one_plane", one_plane_scene(108, 1000), o);
  o.balance = Balance::width;
  check_both_precisions("one_plane_width", one_plane_scene(109, 1000), o);
}

TEST(DistributedDetect, SlabsThinnerThanTheGhostWidthEqualsSingleRank) {
  DistributedOptions o = base_options();
  o.axis = SlabAxis::x;
  const std::size_t k = check_both_precisions("thin", thin_scene(110, 1500), o);
  if (session().rank() == 0) {
    EXPECT_GT(k, 100u);
  }
  o.balance = Balance::width;
  check_both_precisions("thin_width", thin_scene(111, 1500), o);
}

// --memory-limit (decomposition/pieces.hpp): every rank detects its owned bodies and ghosts in
// ranges of ids that fit, each reporting only the anchors of its range; the result is the single-rank
// engine's.
TEST(DistributedDetect, MemoryLimitPiecesEqualSingleRank) {
  const Scene scene = uniform_scene(112, 3000);
  const std::string path = write_shared("pieces", scene);
  for (SceneRead read : {SceneRead::own_rows, SceneRead::all_rows}) {
    DistributedOptions o = base_options();
    o.read = read;
    o.memory_limit = 160000;  // bytes: the bodies held and a few hundred contacts a piece
    const std::string what =
        std::string("pieces") + (read == SceneRead::own_rows ? " (own rows)" : " (every row)");
    const std::size_t k = check_equal_to_single_rank<double>(path, scene, o, what);
    check_equal_to_single_rank<float>(path, scene, o, what);
    const DistributedResult<double> r = distributed_detect<double>(session(), path, o);
    EXPECT_GE(r.pieces, 2u) << what;
    EXPECT_GE(r.piece_detections, r.pieces) << what;
    if (session().rank() == 0) {
      EXPECT_GT(k, 200u);
    }
  }
}

TEST(DistributedDetect, MoreRanksThanBodiesEqualsSingleRank) {
  Scene s;
  s.sphere_position = {{0, 0, 0}, {1.5, 0, 0}, {3.0, 0.1, 0}};
  s.sphere_radius = {1.0, 0.8, 0.9};
  const std::size_t k = check_both_precisions("three", s);
  if (session().rank() == 0) {
    EXPECT_EQ(k, 2u);
  }
}

TEST(DistributedDetect, OneBodyEqualsSingleRank) {
  Scene s;
  s.sphere_position = {{1, 2, 3}};
  s.sphere_radius = {0.5};
  const std::size_t k = check_both_precisions("one", s);
  if (session().rank() == 0) {
    EXPECT_EQ(k, 0u);
  }
}

TEST(DistributedDetect, TinyGatherRoundsAndSmallSampleEqualsSingleRank) {
  DistributedOptions o = base_options();
  o.max_message_bytes = 64;  // many gather rounds of a few elements
  o.max_sample = 37;         // approximate quantiles from a regular sample
  check_both_precisions("tiny_rounds", uniform_scene(112, 1200), o);
}

TEST(DistributedDetect, ExplicitCellSizeEqualsSingleRank) {
  DistributedOptions o = base_options();
  o.engine.cell_size = 5.0;
  check_both_precisions("cell5", uniform_scene(113, 1000), o);
}

// A few large bodies among small ones (generate's intruders, bimodal): the large ones go as ghosts to
// every slab they reach, the small ones only as far as small partners need them (GhostRule), and the
// pair of a large and a small body is the small one's owner's. Every broad phase.
Scene two_size_scene(const std::string& kind, std::uint64_t seed, std::uint64_t n, double r_high = 2.0) {
  GenerateOptions g;
  g.kind = kind;
  g.count = n;
  g.seed = seed;
  g.radius_low = 0.05;
  g.radius_high = r_high;  // 1:40 by default
  g.intruders = 7;
  g.large_fraction = 0.3;
  return generate_scene(g);
}

TEST(DistributedDetect, IntrudersAndBimodalEqualSingleRank) {
  for (const char* kind : {"intruders", "bimodal"}) {
    const std::size_t k = check_both_precisions(kind, two_size_scene(kind, 115, 3000));
    if (session().rank() == 0) {
      EXPECT_GT(k, 500u) << kind;
    }
  }
  for (BroadPhase bp : {BroadPhase::grid, BroadPhase::sweep, BroadPhase::brute}) {
    DistributedOptions o = base_options();
    o.engine.broad_phase = bp;
    check_both_precisions(std::string("intruders_") + to_string(bp), two_size_scene("intruders", 116, 1500),
                          o);
  }
}

// The small bodies' halos stay small: far fewer ghosts than the uniform width 2·r_max would send.
TEST(DistributedDetect, SmallBodiesHaveSmallHalos) {
  const Scene scene = two_size_scene("intruders", 117, 6000, 1.0);
  const std::string path = write_shared("small_halos", scene);
  DistributedOptions o = base_options();
  o.axis = SlabAxis::x;
  const DistributedResult<double> r = distributed_detect<double>(session(), path, o);
  if (session().size() == 1) {
    EXPECT_EQ(r.ghosts, 0u);
    return;
  }
  const SlabDecomposition slabs(0, r.cuts);
  const double width = ghost_width(1.0, 1e3, 1e-16);
  std::uint64_t uniform = 0;  // what every body within 2·r_max of another slab would make
  for (const Vec3<double>& p : scene.sphere_position)
    slabs.for_each_ghost_rank(p.x, width, [&](int) { ++uniform; });
  EXPECT_GT(uniform, 0u);
  EXPECT_LT(4 * r.ghosts, uniform) << r.ghosts << " ghosts";
}

TEST(DistributedDetect, CountBalanceGivesEvenOwnership) {
  const Scene scene = uniform_scene(114, 2001);
  const std::string path = write_shared("balance", scene);
  DistributedResult<double> r = distributed_detect<double>(session(), path, base_options());
  const std::size_t p = static_cast<std::size_t>(session().size());
  EXPECT_GE(r.owned_min, scene.size() / p);
  EXPECT_LE(r.owned_max, (scene.size() + p - 1) / p);
  if (p == 1) {
    EXPECT_EQ(r.ghosts, 0u);
  }
}

// ---- errors: every rank ends with the same exception ------------------------------------------------

TEST(DistributedDetect, MissingFileIsAnInputErrorOnEveryRank) {
  EXPECT_THROW(
      distributed_detect<double>(session(), testing::shared_temp_dir() + "/missing.h5", base_options()),
      InputError);
}

// Own rows: only the last rank reads the bad row, and every rank reports its error. Every row: each
// rank finds it; the lowest failing rank's message (rank 0) is the one every rank reports.
TEST(DistributedDetect, BadRowIsReportedByEveryRank) {
  Scene s = uniform_scene(115, 100);
  s.sphere_radius.back() = -1.0;  // row 99: in the last rank's partition
  const std::string path = write_shared("bad_radius", s);
  for (SceneRead read : {SceneRead::own_rows, SceneRead::all_rows}) {
    DistributedOptions o = base_options();
    o.read = read;
    std::string message;
    try {
      distributed_detect<double>(session(), path, o);
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      message = e.what();
    }
    EXPECT_NE(message.find("row 99"), std::string::npos) << message;
    if (session().uses_mpi()) {
      const int failing = read == SceneRead::own_rows || session().size() == 1 ? session().size() - 1 : 0;
      const std::string who =
          "[rank " + std::to_string(failing) + "/" + std::to_string(session().size()) + "]";
      EXPECT_NE(message.find(who), std::string::npos) << message;
      EXPECT_NE(message.find("read"), std::string::npos) << message;
    }
  }
}

TEST(DistributedDetect, InvalidOptionsAreUsageErrorsBeforeCommunication) {
  const std::string path = write_shared("options", uniform_scene(116, 10));
  DistributedOptions o = base_options();
  o.axis = static_cast<SlabAxis>(5);
  EXPECT_THROW(distributed_detect<double>(session(), path, o), UsageError);
  o = base_options();
  o.engine.cell_size = -1;
  EXPECT_THROW(distributed_detect<float>(session(), path, o), UsageError);
  o = base_options();
  o.engine.cell_size = 0.1;  // smaller than 2·r_max: refused by make_frame on every rank
  EXPECT_THROW(distributed_detect<double>(session(), path, o), UsageError);
}

// ---- the session -----------------------------------------------------------------------------------

TEST(Session, RanksAndCollectives) {
  Session& s = session();
  EXPECT_GE(s.rank(), 0);
  EXPECT_LT(s.rank(), s.size());
  EXPECT_GE(s.local_rank(), 0);
  EXPECT_LT(s.local_rank(), s.local_size());
  EXPECT_LE(s.local_size(), s.size());
  EXPECT_EQ(s.device_for(0), -1);
  EXPECT_EQ(s.device_for(1), 0);
  EXPECT_EQ(s.device_for(2), s.local_rank() % 2);
  EXPECT_EQ(s.broadcast(s.rank() == 0 ? "hello" : ""), "hello");
  EXPECT_EQ(s.sum(1), static_cast<unsigned long long>(s.size()));
  EXPECT_EQ(s.max(static_cast<double>(s.rank())), static_cast<double>(s.size() - 1));
  EXPECT_TRUE(s.all(true));
  EXPECT_FALSE(s.all(s.rank() != s.size() - 1));
  EXPECT_EQ(s.prefix(), "[rank " + std::to_string(s.rank()) + "/" + std::to_string(s.size()) + "] ");
}

TEST(Session, AgreeRethrowsTheLowestFailingRanksError) {
  Session& s = session();
  EXPECT_NO_THROW(s.agree(nullptr, "nothing"));
  std::exception_ptr e;
  if (s.rank() == s.size() - 1) e = std::make_exception_ptr(IoError("disk full"));
  try {
    s.agree(e, "write");
    ADD_FAILURE() << "no error";
  } catch (const IoError& x) {
    if (s.uses_mpi()) {
      EXPECT_EQ(std::string(x.what()), "[rank " + std::to_string(s.size() - 1) + "/" +
                                           std::to_string(s.size()) + "] write: disk full");
    }
  }
}

}  // namespace
}  // namespace cg
