// The broad phases (EngineOptions::broad_phase: grid, levels, sweep, brute; kernels/broad_phase.hpp)
// give the same contacts bit for bit — and, with the sphere tests of the default filters, the same
// candidates — on every scene kind (generated: uniform, log-uniform 1:1000, bimodal 1:10 and 1:100,
// intruders 1:100; adversarial: clusters, one cell, cell boundaries, coincident and exactly tangent
// centres; shapes: mixed spheres and ellipsoids, ellipsoids alone with the centre cut), in every
// precision mode (fp32, fp64, mixed), with a report mask and with a skin, on both backends (CUDA
// cases skip visibly without a GPU). The grid is the reference here; its own oracle is the exact
// reference of test_engine.cpp, and the brute broad phase shares none of its cell logic.
// Also: the levels' plan, the sweep's sortable keys, and the rule of `auto`.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "backend.hpp"
#include "backends.hpp"
#include "broad_phase.hpp"
#include "core/contact.hpp"
#include "engine.hpp"
#include "grid_plan.hpp"
#include "host/stages.hpp"
#include "scene/generate.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"

namespace cg::test {
namespace {

constexpr BroadPhase kOthers[] = {BroadPhase::levels, BroadPhase::sweep, BroadPhase::brute};
constexpr Precision kModes[] = {Precision::fp32, Precision::fp64, Precision::mixed};

// A scene of any kind: spheres, or bodies with shape rows.
struct TestScene {
  std::string name;
  std::vector<Vec3<double>> p;
  std::vector<double> r;
  std::vector<Shape> shape;
  std::vector<Vec3<double>> axes;
  std::vector<Quat<double>> q;
  std::vector<std::uint8_t> report;
  BodiesView view() const {
    BodiesView v{p, r, {}, report};
    v.shape = shape;
    v.semi_axes = axes;
    v.orientation = q;
    return v;
  }
};

TestScene from(const Spheres& s) { return {s.name, s.p, s.r, {}, {}, {}, {}}; }
TestScene from(const ShapeScene& s) { return {s.name, s.p, s.r, s.shape, s.axes, s.q, {}}; }

TestScene generated(const std::string& kind, std::uint64_t n, double r_low, double r_high, std::uint64_t seed,
                    std::uint64_t intruders = 3) {
  GenerateOptions o;
  o.kind = kind;
  o.count = n;
  o.seed = seed;
  o.radius_low = r_low;
  o.radius_high = r_high;
  o.intruders = intruders;
  const Scene g = generate_scene(o);
  TestScene s;
  s.name = kind + " 1:" + std::to_string(int(std::lround(r_high / r_low)));
  s.p.assign(g.sphere_position.begin(), g.sphere_position.end());
  s.r.assign(g.sphere_radius.begin(), g.sphere_radius.end());
  return s;
}

std::vector<TestScene> scenes(std::uint64_t seed) {
  std::vector<TestScene> s;
  s.push_back(generated("uniform", 3000, 0.5, 1, seed));
  s.push_back(generated("polydisperse", 3000, 0.001, 1, seed + 1));
  s.push_back(generated("bimodal", 3000, 0.1, 1, seed + 2));
  s.push_back(generated("bimodal", 4000, 0.01, 1, seed + 3));
  s.push_back(generated("intruders", 4000, 0.01, 1, seed + 4));
  s.push_back(from(clustered(1500, seed + 5)));
  s.push_back(from(one_cell(200, seed + 6)));
  s.push_back(from(on_boundaries(seed + 7)));
  s.push_back(from(coincident(seed + 8)));
  s.push_back(from(tangent(seed + 9)));
  s.push_back(from(random_spheres(2000, 0.01, 2.0, seed + 10, true).translated({1e5, -3e4, 7})));
  s.push_back(from(make_scene("mixed shapes", std::uint32_t(seed + 11), 500, 0.5, 12)));
  s.push_back(from(make_scene("ellipsoids (centre cut)", std::uint32_t(seed + 12), 500, 1.0, 12)));
  return s;
}

struct Run {
  Contacts<double> contacts;   // fp64, mixed
  Contacts<float> contacts32;  // fp32
  EngineStats stats;
};

template <Backend B>
Run detect(const TestScene& s, Precision mode, BroadPhase bp, double skin = 0) {
  EngineOptions o;
  o.backend = B;
  o.fields = Fields::full;
  o.broad_phase = bp;
  o.fp32_broad_phase = mode == Precision::mixed;
  o.skin = skin;
  Run run;
  if (mode == Precision::fp32) {
    Engine<float> e(o);
    run.contacts32 = e.detect(s.view());
    run.stats = e.stats();
  } else {
    Engine<double> e(o);
    run.contacts = e.detect(s.view());
    run.stats = e.stats();
  }
  return run;
}

std::string same(const Run& got, const Run& want) {
  const std::string a = compare_contacts(got.contacts, want.contacts);
  const std::string b = compare_contacts(got.contacts32, want.contacts32);
  return a != "identical" ? a : b;
}

template <class T>
class BroadPhaseTest : public ::testing::Test {};
TYPED_TEST_SUITE(BroadPhaseTest, BackendTypes, BackendTypeNames);

// Every scene, every mode, every broad phase: the grid's contacts, bit for bit; the sphere filters'
// candidates too (the centre cut's grid takes the shapes' boxes: there only the contacts agree).
TYPED_TEST(BroadPhaseTest, EveryBroadPhaseGivesTheGridsContacts) {
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  constexpr Backend B = TypeParam::backend;
  for (const TestScene& s : scenes(101))
    for (Precision mode : kModes) {
      const Run grid = detect<B>(s, mode, BroadPhase::grid);
      ASSERT_EQ(grid.stats.broad_phase, BroadPhase::grid);
      ASSERT_GT(grid.stats.contacts, 0u) << s.name;
      const bool centre_cut = 5 * grid.stats.ellipsoids >= 4 * grid.stats.bodies;
      for (BroadPhase bp : kOthers) {
        const Run other = detect<B>(s, mode, bp);
        SCOPED_TRACE(s.name + ", " + to_string(mode) + ", " + to_string(bp));
        EXPECT_EQ(other.stats.broad_phase, bp);
        EXPECT_EQ(same(other, grid), "identical");
        if (!centre_cut) {
          EXPECT_EQ(other.stats.candidates, grid.stats.candidates);
        }
        EXPECT_EQ(other.stats.narrow_fallbacks, grid.stats.narrow_fallbacks);
        EXPECT_EQ(other.stats.fp64_rows, grid.stats.fp64_rows);
      }
    }
}

// A report mask (a rank's owned bodies and ghosts): the same reported pairs whichever broad phase.
TYPED_TEST(BroadPhaseTest, ReportMaskIsObeyed) {
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  constexpr Backend B = TypeParam::backend;
  std::vector<TestScene> all = scenes(202);
  for (std::size_t k : {std::size_t(2), std::size_t(4), std::size_t(11)}) {
    TestScene s = all[k];
    s.report.resize(s.r.size());
    for (std::size_t i = 0; i < s.r.size(); ++i)
      s.report[i] =
          static_cast<std::uint8_t>(((i % 3) != 0 ? kReportedBit : 0) | (i % 5 < 2 ? kPairedBit : 0));
    for (Precision mode : kModes) {
      const Run grid = detect<B>(s, mode, BroadPhase::grid);
      for (BroadPhase bp : kOthers) {
        SCOPED_TRACE(s.name + " (mask), " + to_string(mode) + ", " + to_string(bp));
        EXPECT_EQ(same(detect<B>(s, mode, bp), grid), "identical");
      }
    }
  }
}

// The wide bit (bodies.hpp): of a wide and a narrow body, the narrow one's report flag decides; of
// two alike, the smaller id's (and never two paired bodies). Every broad phase, every mode, against
// the rule applied to all the contacts.
TYPED_TEST(BroadPhaseTest, WideBitsGiveThePairToTheNarrowBody) {
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  constexpr Backend B = TypeParam::backend;
  TestScene s = generated("intruders", 3000, 0.01, 1, 404, 12);
  std::mt19937_64 rng(404);
  s.report.resize(s.r.size());
  for (std::size_t i = 0; i < s.r.size(); ++i)
    s.report[i] =
        static_cast<std::uint8_t>((rng() % 3 != 0 ? kReportedBit : 0) | (rng() % 7 == 0 ? kPairedBit : 0) |
                                  (s.r[i] > 0.5 ? kWideBit : 0));
  TestScene plain = s;
  plain.report.clear();
  for (Precision mode : kModes) {
    const Run all = detect<B>(plain, mode, BroadPhase::grid);
    const auto& ia = mode == Precision::fp32 ? all.contacts32.id_a : all.contacts.id_a;
    const auto& ib = mode == Precision::fp32 ? all.contacts32.id_b : all.contacts.id_b;
    std::vector<std::pair<std::int64_t, std::int64_t>> want;
    std::size_t by_narrow = 0;
    for (std::size_t k = 0; k < ia.size(); ++k) {
      const std::uint8_t ra = s.report[std::size_t(ia[k])], rb = s.report[std::size_t(ib[k])];
      const bool wa = ra & kWideBit, wb = rb & kWideBit;
      const std::uint8_t anchor = wa != wb ? (wa ? rb : ra) : ra;
      if (!(anchor & kReportedBit) || ((ra & kPairedBit) && (rb & kPairedBit))) continue;
      by_narrow += wa && !wb;
      want.emplace_back(ia[k], ib[k]);
    }
    ASSERT_GT(by_narrow, 100u) << "the scene exercises the rule";
    for (BroadPhase bp : {BroadPhase::grid, BroadPhase::levels, BroadPhase::sweep, BroadPhase::brute}) {
      SCOPED_TRACE(std::string(to_string(mode)) + ", " + to_string(bp));
      const Run got = detect<B>(s, mode, bp);
      const auto& ga = mode == Precision::fp32 ? got.contacts32.id_a : got.contacts.id_a;
      const auto& gb = mode == Precision::fp32 ? got.contacts32.id_b : got.contacts.id_b;
      std::vector<std::pair<std::int64_t, std::int64_t>> have;
      for (std::size_t k = 0; k < ga.size(); ++k) have.emplace_back(ga[k], gb[k]);
      EXPECT_EQ(have, want);
    }
  }
}

// A skin: the inflated spheres make the candidates, the contacts stay a skin-0 detection's.
TYPED_TEST(BroadPhaseTest, SkinKeepsTheContacts) {
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  constexpr Backend B = TypeParam::backend;
  std::vector<TestScene> all = scenes(303);
  for (std::size_t k : {std::size_t(3), std::size_t(4), std::size_t(12)})
    for (Precision mode : kModes) {
      const Run grid = detect<B>(all[k], mode, BroadPhase::grid, 0.05);
      EXPECT_EQ(same(grid, detect<B>(all[k], mode, BroadPhase::grid)), "identical");
      for (BroadPhase bp : kOthers) {
        SCOPED_TRACE(all[k].name + " (skin), " + to_string(mode) + ", " + to_string(bp));
        const Run other = detect<B>(all[k], mode, bp, 0.05);
        EXPECT_EQ(same(other, grid), "identical");
        EXPECT_EQ(other.stats.candidates, grid.stats.candidates);
      }
    }
}

// A large body reaches every level: the levels of 1:1000 sizes, and the pairs across them.
TYPED_TEST(BroadPhaseTest, LevelsSpanTheSizes) {
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  constexpr Backend B = TypeParam::backend;
  const TestScene s = generated("polydisperse", 3000, 0.001, 1, 7);
  const Run levels = detect<B>(s, Precision::fp64, BroadPhase::levels);
  EXPECT_EQ(levels.stats.levels, 10);  // tops 0.002 … 0.512, then the rest
  const Run one = detect<B>(generated("uniform", 2000, 0.5, 1, 8), Precision::fp64, BroadPhase::levels);
  EXPECT_EQ(one.stats.levels, 1);  // radii within a factor 2: one level, the grid itself
  // three bodies of r = 1 among grains of r = 0.01: the grid's one cell holds every grain, the
  // levels test a few pairs per grain (a few dozen: the grains' cells follow the cost model, which
  // trades pair tests for fewer entries)
  const TestScene in = generated("intruders", 3000, 0.01, 1, 9);
  const Run grid = detect<B>(in, Precision::fp64, BroadPhase::grid),
            lv = detect<B>(in, Precision::fp64, BroadPhase::levels);
  EXPECT_EQ(lv.stats.levels, 7);
  EXPECT_LT(lv.stats.pair_tests * 50, grid.stats.pair_tests);
  EXPECT_LT(lv.stats.pair_tests, 40 * in.r.size());
}

TYPED_TEST(BroadPhaseTest, AutoPicksByTheRadii) {
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  constexpr Backend B = TypeParam::backend;
  EXPECT_EQ(detect<B>(generated("uniform", 3000, 0.5, 1, 9), Precision::fp64, BroadPhase::automatic)
                .stats.broad_phase,
            BroadPhase::grid);
  EXPECT_EQ(detect<B>(generated("intruders", 3000, 0.01, 1, 9), Precision::fp64, BroadPhase::automatic)
                .stats.broad_phase,
            BroadPhase::levels);
  EXPECT_EQ(detect<B>(generated("uniform", 20, 0.5, 1, 9), Precision::fp64, BroadPhase::automatic)
                .stats.broad_phase,
            BroadPhase::brute);
  // radii log-uniform over 1:1000 at the generator's density: cells of edge 2·r_max hold a few bodies
  EXPECT_EQ(detect<B>(generated("polydisperse", 3000, 0.001, 1, 9), Precision::fp64, BroadPhase::automatic)
                .stats.broad_phase,
            BroadPhase::grid);
}

// Resident bodies (Engine::set_resident, detect_resident; on CUDA: their bounds from the device, the
// path of bench-broad and of the step loops) plan what the host arrays plan: the same broad phase
// under auto, the same levels, as many pair tests and the same contacts. The levels and auto size
// themselves by the smallest radius; bounds without it plan one level, the grid, and the intruder's
// grains then crowd the grid's cells.
TYPED_TEST(BroadPhaseTest, ResidentBodiesPlanTheLevelsOfTheHostArrays) {
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  constexpr Backend B = TypeParam::backend;
  for (const TestScene& s :
       {generated("intruders", 3000, 0.01, 1, 9, 1), generated("bimodal", 4000, 0.1, 1, 10),
        generated("polydisperse", 3000, 0.001, 1, 11)})
    for (BroadPhase bp : {BroadPhase::levels, BroadPhase::automatic}) {
      SCOPED_TRACE(s.name + ", " + to_string(bp));
      const Run host = detect<B>(s, Precision::fp32, bp);
      EngineOptions o;
      o.backend = B;
      o.fields = Fields::full;
      o.broad_phase = bp;
      Engine<float> e(o);
      e.set_resident(s.view());
      e.detect_resident();
      EXPECT_EQ(compare_contacts(e.resident_contacts(), host.contacts32), "identical");
      EXPECT_EQ(e.stats().broad_phase, host.stats.broad_phase);
      EXPECT_EQ(e.stats().levels, host.stats.levels);
      // (the device sums the radius moments of the cell-size model in another order: the frame's edge,
      // and with it the top level's tests, may differ by a rounding)
      EXPECT_NEAR(double(e.stats().pair_tests), double(host.stats.pair_tests),
                  0.1 * double(host.stats.pair_tests));
      // (the bimodal scene of 4000 bodies holds no r = 1 body at 10 % of the volume: one level)
      if (bp == BroadPhase::levels && s.name.rfind("bimodal", 0) != 0) {
        EXPECT_GE(e.stats().levels, 3);
      }
    }
}

// The levels' work is near-linear in N on one r = 1 intruder among r = 0.01 grains (issue #34): the
// pair tests per body of 2^15 bodies within 1.5x of those of 2^12 (the grid's grow with N: every
// grain of the intruder's cells meets every other), host arrays and resident bodies alike.
TYPED_TEST(BroadPhaseTest, LevelsPairTestsGrowLinearlyWithOneIntruder) {
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  constexpr Backend B = TypeParam::backend;
  double per_body[2][2] = {};
  const std::uint64_t sizes[2] = {4096, 32768};
  for (int k = 0; k < 2; ++k) {
    const TestScene s = generated("intruders", sizes[k], 0.01, 1, 12, 1);
    const Run host = detect<B>(s, Precision::fp32, BroadPhase::levels);
    EngineOptions o;
    o.backend = B;
    o.broad_phase = BroadPhase::levels;
    Engine<float> e(o);
    e.set_resident(s.view());
    e.detect_resident();
    per_body[k][0] = double(host.stats.pair_tests) / double(sizes[k]);
    per_body[k][1] = double(e.stats().pair_tests) / double(sizes[k]);
  }
  for (int path = 0; path < 2; ++path) {
    SCOPED_TRACE(path == 0 ? "host arrays" : "resident");
    EXPECT_GT(per_body[0][path], 0.5);
    EXPECT_LT(per_body[1][path], 1.5 * per_body[0][path]);
    EXPECT_LT(per_body[1][path], 20.0);
  }
}

// ---- plans and keys ---------------------------------------------------------------------------------

Bounds bounds_of(double r_min, double r_max, double extent, std::uint64_t n = 1000) {
  Bounds b;
  b.lo = {0, 0, 0};
  b.hi = {extent, extent, extent};
  b.r_min = r_min;
  b.r_max = r_max;
  b.count = n;
  b.r_sum[0] = double(n) * r_min;
  return b;
}

TEST(LevelsPlan, TopsDoubleAndCellsCoverThem) {
  const Bounds b = bounds_of(0.01, 1, 50);
  const Frame f = make_frame(b, 0, Precision::fp64, CellChoice::smallest);
  const LevelsPlan plan = plan_levels(b, f, Precision::fp64, 0);
  ASSERT_EQ(plan.count, 7);  // 0.02, 0.04, …, 0.64, then the rest
  for (int l = 0; l + 1 < plan.count; ++l) {
    EXPECT_DOUBLE_EQ(plan.top[l], 0.01 * std::pow(2.0, l + 1));
    EXPECT_GE(plan.grid[l].frame.cell_size, 2 * plan.top[l]);
    // the cost model's edge: at most the next level's smallest
    EXPECT_LT(plan.grid[l].frame.cell_size, 2.01 * (l + 2 < plan.count ? plan.top[l + 1] : f.cell_size));
    EXPECT_EQ(plan.grid[l].half_bits, plan.half_bits);
  }
  EXPECT_TRUE(std::isinf(plan.top[plan.count - 1]));
  EXPECT_EQ(plan.grid[plan.count - 1].frame.cell_size, f.cell_size);
  EXPECT_EQ(plan.key_bits, plan.half_bits + 3 + 3);
  const LevelParams<float> lp = level_params<float>(plan, 0);
  EXPECT_EQ(level_of(0.01f, lp), 0);
  EXPECT_EQ(level_of(0.03f, lp), 1);
  EXPECT_EQ(level_of(0.5f, lp), 5);
  EXPECT_EQ(level_of(0.7f, lp), 6);
  EXPECT_EQ(level_of(1.0f, lp), 6);
}

TEST(LevelsPlan, TheFinestLevelTakesTheCostModelsWiderEdge) {
  // 2^16 grains of r = 0.1 and a few bodies of r = 1, spread thin: the grains' level takes the widest
  // edge the model allows (the next level's smallest), so their boxes span fewer cells than in cells
  // of twice its top; the edges never shrink up the levels
  const Bounds b = bounds_of(0.1, 1, 100, std::uint64_t(1) << 16);
  const Frame f = make_frame(b, 0, Precision::fp64);
  const LevelsPlan plan = plan_levels(b, f, Precision::fp64, 0);
  ASSERT_GE(plan.count, 2);
  EXPECT_GT(plan.grid[0].frame.cell_size, 1.5 * 2 * plan.top[0]);
  for (int l = 0; l + 1 < plan.count; ++l)
    EXPECT_LE(plan.grid[l].frame.cell_size, plan.grid[l + 1].frame.cell_size) << l;
  // a dense scene keeps the smallest edge (the pair walk's steps outweigh the entries)
  const Bounds dense = bounds_of(0.1, 1, 6, std::uint64_t(1) << 16);
  const LevelsPlan packed = plan_levels(dense, make_frame(dense, 0, Precision::fp64), Precision::fp64, 0);
  EXPECT_LT(packed.grid[0].frame.cell_size, 1.01 * 2 * packed.top[0]);
}

TEST(LevelsPlan, SpreadBeyondTheLevelsWidensTheRatio) {
  const Bounds b = bounds_of(1e-6, 1, 10);
  const LevelsPlan plan = plan_levels(b, make_frame(b, 0, Precision::fp64), Precision::fp64, 0);
  EXPECT_LE(plan.count, kMaxLevels);
  EXPECT_GE(plan.count, kMaxLevels - 3);     // (the finest cannot be keyed in 63 bits: merged)
  EXPECT_GT(plan.top[plan.count - 2], 0.3);  // the last finite top reaches the largest radii
  EXPECT_LE(plan.key_bits, 63);
}

TEST(LevelsPlan, FinestLevelsMergeWhenTheirGridsCannotBeKeyed) {
  // fp64: 1e-4 bodies across 1e6 would need 5·10^9 cells per axis (more than 2^31), and any grid
  // finer than 2^20 super-cells per axis more than 63 key bits with the levels' own
  const Bounds b = bounds_of(1e-4, 1, 1e6);
  const LevelsPlan plan = plan_levels(b, make_frame(b, 0, Precision::fp64), Precision::fp64, 0);
  ASSERT_GE(plan.count, 1);
  EXPECT_LE(plan.count, 4);     // (of the 14 the radii span)
  EXPECT_GT(plan.top[0], 0.1);  // the smallest bodies in a coarser level
  EXPECT_LE(plan.key_bits, 63);
  for (int l = 0; l < plan.count; ++l) EXPECT_LT(double(plan.grid[l].dims[0]), double(1u << 31)) << l;
}

TEST(LevelsPlan, LevelsOfOneCellEdgeMerge) {
  // fp32 far from the origin: the coordinates' rounding margin (16·ε32·1e4 = 0.019) sets the smallest
  // cells, so the finest tops share one edge: one level of them
  const Bounds b = bounds_of(0.001, 1, 1e4);
  const LevelsPlan plan = plan_levels(b, make_frame(b, 0, Precision::fp32), Precision::fp32, 0);
  ASSERT_GE(plan.count, 2);
  EXPECT_LT(plan.count, 10);
  for (int l = 0; l + 1 < plan.count; ++l)
    EXPECT_LE(plan.grid[l].frame.cell_size, 0.75 * plan.grid[l + 1].frame.cell_size) << l;
}

TEST(SweepKeys, OrderAsTheValues) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1e6, 1e6);
  std::vector<double> v{
      0.0, -0.0, 1e-300, -1e-300, std::numeric_limits<double>::max(), -std::numeric_limits<double>::max()};
  for (int i = 0; i < 1000; ++i) v.push_back(u(rng));
  for (double a : v)
    for (double b : {v[0], v[3], v[7], v[100]}) {
      if (a < b) {
        EXPECT_LT(orderable_bits(a), orderable_bits(b));
      }
      if (float(a) < float(b)) {
        EXPECT_LT(orderable_bits(float(a)), orderable_bits(float(b)));
      }
    }
}

TEST(BoxRadius, EverySphereTestPairHasOverlappingBoxes) {
  // pairs at the sphere test's rounding edge along one axis: accepted ones overlap as boxes
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<float> u(-1000, 1000), ur(0.001f, 2);
  int accepted = 0;
  for (int i = 0; i < 200000; ++i) {
    const float x = u(rng), ra = ur(rng), rb = ur(rng);
    float y = x + (ra + rb);
    for (int step = 0; step < int(rng() % 4); ++step) y = std::nextafter(y, 1e30f);
    const Sphere<float> a{x, 0, 0, ra}, b{y, 0, 0, rb};
    if (!spheres_touch(a, b)) continue;
    ++accepted;
    EXPECT_TRUE(boxes_overlap(a, b)) << x << " " << y << " " << ra << " " << rb;
  }
  EXPECT_GT(accepted, 1000);
}

TEST(AutoBroadPhase, Rule) {
  EXPECT_EQ(choose_broad_phase(bounds_of(0.5, 1, 100, 20), Precision::fp64), BroadPhase::brute);
  Bounds uniform = bounds_of(0.5, 1, 100, 100000);
  uniform.r_sum[0] = 0.75 * 100000;
  EXPECT_EQ(choose_broad_phase(uniform, Precision::fp64), BroadPhase::grid);
  // one r = 1 among 10^5 grains of r = 0.01 in a cube of edge 3.2: a cell of the grid (edge 2) holds
  // 2.4·10^4 grains
  Bounds intruder = bounds_of(0.01, 1, 3.2, 100000);
  intruder.r_sum[0] = 0.01 * 99999 + 1;
  EXPECT_NEAR(grid_occupancy(intruder), 100000 * 8.0 / (3.2 * 3.2 * 3.2), 1e-6);
  EXPECT_EQ(choose_broad_phase(intruder, Precision::fp64), BroadPhase::levels);
  // the same radii spread over a cube of edge 100: cells of edge 2 hold one body in a hundred, the
  // grid stays cheap and the levels' lookups would cost more
  Bounds sparse = bounds_of(0.01, 1, 100, 100000);
  sparse.r_sum[0] = 0.01 * 99999 + 1;
  EXPECT_LT(grid_occupancy(sparse), 1.0);
  EXPECT_EQ(choose_broad_phase(sparse, Precision::fp64), BroadPhase::grid);
  EXPECT_EQ(choose_broad_phase(sparse, Precision::fp64, true), BroadPhase::grid);
  EXPECT_EQ(choose_broad_phase(intruder, Precision::fp64, true), BroadPhase::levels);
  EXPECT_EQ(choose_broad_phase(uniform, Precision::fp64, true), BroadPhase::grid);
  // bimodal 1:10 (10 % of the volume in r = 1 among r = 0.1) at the generator's density: a cell of
  // edge 2 holds ~164 bodies over log2(20) = 4.3 levels: the host's grid, a GPU's levels (its grid
  // walks cells longer than its staged window from memory)
  Bounds bimodal = bounds_of(0.1, 1, 23.4, 262144);
  bimodal.r_sum[0] = 0.1 * 262144 * 1.0;
  EXPECT_NEAR(grid_occupancy(bimodal), 163.7, 0.5);
  EXPECT_EQ(choose_broad_phase(bimodal, Precision::fp32), BroadPhase::grid);
  EXPECT_EQ(choose_broad_phase(bimodal, Precision::fp32, true), BroadPhase::levels);
  // log-uniform 1:1000 at the generator's density: ~9 bodies a cell over 11 levels, the grid's on both
  Bounds loguniform = bounds_of(0.001, 1, 61.8, 262144);
  loguniform.r_sum[0] = 262144 * 0.145;
  EXPECT_NEAR(grid_occupancy(loguniform), 8.9, 0.1);
  EXPECT_EQ(choose_broad_phase(loguniform, Precision::fp32), BroadPhase::grid);
  EXPECT_EQ(choose_broad_phase(loguniform, Precision::fp32, true), BroadPhase::grid);
  // one size class (r_max <= 2 r_min: one level) from 2^21 bodies, sparse: the levels' walk on a GPU,
  // the grid on the host; below 2^21, denser scenes and wider radius laws, as above. Radii U[0.5, 1]
  // (moments 0.75, 7/12, 15/32) in a cube of edge 340: 0.4 expected contacts a body, the generator's
  const std::uint64_t many = std::uint64_t(1) << 21;  // broad_phase.cpp's kOneLevelDeviceBodies
  Bounds large_uniform = bounds_of(0.5, 1, 340, many);
  large_uniform.r_sum[0] = 0.75 * double(many);
  large_uniform.r_sum[1] = 7.0 / 12.0 * double(many);
  large_uniform.r_sum[2] = 15.0 / 32.0 * double(many);
  EXPECT_NEAR(expected_contacts_per_body(large_uniform), 0.398, 0.002);
  EXPECT_EQ(choose_broad_phase(large_uniform, Precision::fp32, true), BroadPhase::levels);
  EXPECT_EQ(choose_broad_phase(large_uniform, Precision::fp64, false), BroadPhase::grid);
  // the same bodies at a granular density (edge 150: 4.6 a body; the crossover is 1.5): the grid
  Bounds dense_uniform = large_uniform;
  dense_uniform.hi = {150, 150, 150};
  EXPECT_GT(expected_contacts_per_body(dense_uniform), kOneLevelContactsPerBody);
  EXPECT_EQ(choose_broad_phase(dense_uniform, Precision::fp32, true), BroadPhase::grid);
  // without moments the estimate takes r_max for every radius: never below the moments' value
  Bounds no_moments = large_uniform;
  no_moments.r_sum[1] = no_moments.r_sum[2] = 0;
  EXPECT_GT(expected_contacts_per_body(no_moments), expected_contacts_per_body(large_uniform));
  // calls that keep their candidates (a skin) keep the grid: the rule's measurement was of fresh calls
  EXPECT_EQ(choose_broad_phase(large_uniform, Precision::fp32, true, true), BroadPhase::grid);
  // so do engines whose skin is chosen per call (skin_auto, skin 0 until then), as the engine and the
  // detect pipeline resolve it (keeps_candidates); a fixed skin as before, no skin the levels
  EngineOptions automatic, fixed, none;
  automatic.skin_auto = true;
  fixed.skin = 0.1;
  for (const auto& [o, want] : {std::pair{automatic, BroadPhase::grid}, std::pair{fixed, BroadPhase::grid},
                                std::pair{none, BroadPhase::levels}})
    EXPECT_EQ(resolved_broad_phase(BroadPhase::automatic, large_uniform, Precision::fp32, Backend::cuda,
                                   keeps_candidates(o)),
              want);
  Bounds fewer = large_uniform;
  fewer.count = many - 1;
  EXPECT_EQ(choose_broad_phase(fewer, Precision::fp32, true), BroadPhase::grid);
  Bounds one_size = bounds_of(0.01, 0.01, 100, 4 * many);  // bimodal 1:100 with no large body drawn
  one_size.r_sum[0] = 0.01 * 4 * double(many);
  EXPECT_EQ(choose_broad_phase(one_size, Precision::fp32, true), BroadPhase::levels);
  Bounds wider = bounds_of(0.49, 1, 200, 4 * many);  // just over one level: the grid, as uniform below
  wider.r_sum[0] = 0.75 * 4 * double(many);
  EXPECT_EQ(choose_broad_phase(wider, Precision::fp32, true), BroadPhase::grid);
  Bounds large_loguniform = bounds_of(0.001, 1, 980, 16 * many);
  large_loguniform.r_sum[0] = 16 * double(many) * 0.145;
  EXPECT_EQ(choose_broad_phase(large_loguniform, Precision::fp32, true), BroadPhase::grid);
  // a flat scene: the extents are at least the cell (the estimate too)
  Bounds flat = bounds_of(0.01, 1, 100, 100000);
  flat.hi.z = 0;
  EXPECT_NEAR(grid_occupancy(flat), 100000 * 8.0 / (100 * 100 * 2), 1e-9);
  EXPECT_GT(expected_contacts_per_body(flat), 0.0);
}

// The density estimate of auto's one-level rule against the contacts of generated scenes (generate's
// --contacts-per-body model, the box's edges included: within 15 %).
TEST(AutoBroadPhase, ExpectedContactsPerBodyMatchTheGenerator) {
  for (const double density : {0.4, 1.5, 6.0}) {
    GenerateOptions g;
    g.count = 1 << 15;
    g.seed = 5;
    g.contacts_per_body = density;
    const Scene scene = generate_scene(g);
    const BodiesView bodies{{scene.sphere_position.data(), scene.sphere_position.size()},
                            {scene.sphere_radius.data(), scene.sphere_radius.size()},
                            {},
                            {}};
    EngineOptions o;
    o.backend = Backend::cpu;
    Engine<double> engine(o);
    const double measured = double(engine.detect(bodies).size()) / double(g.count);
    const double estimate = expected_contacts_per_body(compute_bounds(bodies));
    EXPECT_NEAR(measured, density, 0.15 * density) << "the generator's own density";
    EXPECT_NEAR(estimate, measured, 0.15 * measured) << density;
  }
}

// The CUDA levels against the CPU's on log-uniform 1:1000 scenes of 2^13 bodies (where the device's
// levels once lost 2–3 of ~1 160 candidates), every mode: the same contacts and candidates, bit for
// bit, and the CPU's levels the same as its grid. Skips visibly without a GPU.
TEST(LevelsCpuCuda, SameContactsOnLogUniformScenes) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  for (const std::uint64_t seed : {34u, 102u}) {
    const TestScene s = generated("polydisperse", 8192, 0.001, 1, seed);
    for (Precision mode : kModes) {
      SCOPED_TRACE(s.name + ", seed " + std::to_string(seed) + ", " + to_string(mode));
      const test::Run cpu = detect<Backend::cpu>(s, mode, BroadPhase::levels);
      const test::Run gpu = detect<Backend::cuda>(s, mode, BroadPhase::levels);
      ASSERT_GE(cpu.stats.levels, 8);
      EXPECT_EQ(same(cpu, detect<Backend::cpu>(s, mode, BroadPhase::grid)), "identical");
      EXPECT_EQ(same(gpu, cpu), "identical");
      EXPECT_EQ(gpu.stats.candidates, cpu.stats.candidates);
      EXPECT_EQ(gpu.stats.levels, cpu.stats.levels);
      EXPECT_EQ(gpu.stats.entries, cpu.stats.entries);
    }
  }
}

// The order stage's long runs (cuda/order.cuh: a large body's contacts with the grains of larger
// index, sorted by CUB's segmented sort instead of one thread): three r = 1 intruders among 2^14
// grains of r = 0.01 (the first intruder's run holds thousands of pairs), every broad phase, fp32 and
// fp64: the CUDA contacts are the CPU's, bit for bit. Skips visibly without a GPU.
TEST(OrderCpuCuda, LongRunsOfOneBodyKeepTheHostOrder) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  const TestScene s = generated("intruders", 16384, 0.01, 1, 21, 3);
  for (Precision mode : {Precision::fp32, Precision::fp64}) {
    const test::Run cpu = detect<Backend::cpu>(s, mode, BroadPhase::levels);
    const auto& ia = mode == Precision::fp32 ? cpu.contacts32.id_a : cpu.contacts.id_a;
    std::size_t longest = 0, run = 0;
    for (std::size_t k = 0; k < ia.size(); ++k) {
      run = k > 0 && ia[k] == ia[k - 1] ? run + 1 : 1;
      longest = std::max(longest, run);
    }
    ASSERT_GT(longest, 1000u) << "the scene has a long run";
    for (BroadPhase bp : {BroadPhase::grid, BroadPhase::levels, BroadPhase::sweep}) {
      SCOPED_TRACE(std::string(to_string(mode)) + ", " + to_string(bp));
      EXPECT_EQ(same(detect<Backend::cuda>(s, mode, bp), cpu), "identical");
    }
  }
}

// ---- the CUDA levels' data flow, on the host -------------------------------------------------------
//
// cuda/levels.cuh in the order of its kernels, with the core math they call, on one thread: per body
// its level, the key of its lowest cell and its control byte (level_cells_kernel); its entries from
// those two (spilled_cell_key, level_entries_kernel); the sort over key_bits; each level's run
// (level_begin_kernel); the pairs within a cell (the pair walk: test_in_cell and the sphere test);
// the pairs across levels (cross_level_kernel: cross_level_pairs). Against every pair of the scene
// that touches (all pairs tested), on the radius spreads where the device's levels once lost pairs.
template <class Real, class Key>
std::string device_levels_flow(const TestScene& s, Precision prec) {
  const BodiesView v = s.view();
  const Bounds b = compute_bounds(v);
  const Frame f = make_frame(b, 0, prec);
  const double margin = broad_margin(b, f.origin, prec);
  const GridParams<Real> frame_grid = detail::grid_params<Real>(plan_grid(b, f, prec), margin);
  const LevelsPlan plan = plan_levels(b, f, prec, margin);
  if (plan.key64 != (sizeof(Key) == 8)) return "key width";
  const LevelParams<Real> lp = level_params<Real>(plan, margin);
  detail::host::PackedBodies<Real> pb;
  detail::host::pack(v, f.origin, frame_grid, Real(0), false, 1, pb);
  const auto& sp = pb.spheres;
  const auto n = static_cast<std::uint32_t>(sp.size());
  std::vector<Key> lo_key(n);
  std::vector<std::uint8_t> ctrl(n);
  for (std::uint32_t i = 0; i < n; ++i) {  // level_cells_kernel
    const int l = level_of(sp[i].r, lp);
    const BodyCells bc = body_cells(sp[i], lp.grid[l]);
    ctrl[i] = control_bits(bc);
    lo_key[i] = (Key(l) << lp.key_shift) | cell_key<Key>(bc.lo[0], bc.lo[1], bc.lo[2], lp.grid[l]);
  }
  std::vector<std::pair<Key, std::uint32_t>> entries;  // level_entries_kernel
  const Key low = (Key(1) << lp.key_shift) - Key(1);
  for (std::uint32_t i = 0; i < n; ++i) {
    const int l = key_level(lo_key[i], lp.key_shift);
    for (std::uint32_t m = 0, count = 1u << popcount3((ctrl[i] >> 3) & 7u); m < count; ++m)
      entries.emplace_back(
          (lo_key[i] & ~low) | spilled_cell_key<Key>(lo_key[i] & low, ctrl[i], m, lp.grid[l]), i);
  }
  const Key sorted_bits = plan.key_bits >= 64 ? ~Key(0) : Key((std::uint64_t(1) << plan.key_bits) - 1);
  std::stable_sort(entries.begin(), entries.end(), [&](const auto& x, const auto& y) {
    return (x.first & sorted_bits) < (y.first & sorted_bits);
  });
  std::vector<Key> keys;
  std::vector<std::uint32_t> body;
  for (const auto& [k, i] : entries) {
    keys.push_back(k);
    body.push_back(i);
  }
  const auto ne = static_cast<std::uint32_t>(keys.size());
  std::set<std::pair<std::uint32_t, std::uint32_t>> found;
  std::size_t twice = 0;
  const auto add = [&](std::uint32_t a, std::uint32_t c) {
    if (!found.emplace(std::min(a, c), std::max(a, c)).second) ++twice;
  };
  for (std::uint32_t e = 0; e < ne; ++e)  // the pair walk within each cell of each level
    for (std::uint32_t g = e + 1; g < ne && keys[g] == keys[e]; ++g)
      if (test_in_cell(ctrl[body[e]], ctrl[body[g]], key_type(keys[e], lp.key_shift - 3)) &&
          spheres_touch(sp[body[e]], sp[body[g]]))
        add(body[e], body[g]);
  std::uint32_t begin[kMaxLevels + 1];  // level_begin_kernel
  for (int l = 0; l < lp.count; ++l)
    begin[l] = lower_bound_key(keys.data(), 0u, ne, Key(Key(l) << lp.key_shift));
  begin[lp.count] = ne;
  for (std::uint32_t a = 0; a < n; ++a)  // cross_level_kernel
    cross_level_pairs(
        a, key_level(lo_key[a], lp.key_shift), lp, keys.data(), body.data(), begin, ctrl.data(),
        static_cast<const std::uint8_t*>(nullptr),
        [&](const GridParams<Real>& g) { return body_cells(sp[a], g); },
        [&](std::uint32_t c) {
          if (spheres_touch(sp[a], sp[c])) add(a, c);
        });
  std::size_t want = 0, missed = 0;
  for (std::uint32_t a = 0; a < n; ++a)
    for (std::uint32_t c = a + 1; c < n; ++c)
      if (spheres_touch(sp[a], sp[c])) {
        ++want;
        missed += found.count({a, c}) == 0;
      }
  if (plan.count < 8 || want < 1000) return "the scene does not exercise the levels";
  return "missed " + std::to_string(missed) + ", twice " + std::to_string(twice) + ", extra " +
         std::to_string(found.size() + missed - want);
}

TEST(LevelsDeviceFlow, FindsEveryTouchingPairOfLogUniformScenes) {
  for (const std::uint64_t seed : {34u, 102u}) {
    const TestScene s = generated("polydisperse", 8192, 0.001, 1, seed);
    SCOPED_TRACE(s.name + ", seed " + std::to_string(seed));
    EXPECT_EQ((device_levels_flow<double, std::uint64_t>(s, Precision::fp64)), "missed 0, twice 0, extra 0");
    EXPECT_EQ((device_levels_flow<float, std::uint64_t>(s, Precision::fp32)), "missed 0, twice 0, extra 0");
  }
}

}  // namespace
}  // namespace cg::test
