// Runaway work (kernels/pair_estimate.hpp): the pair tests a broad phase estimates before its pair
// stage bound the tests it then makes, equal them where every body has one cell, and a limit below the
// estimate refuses the scene (LimitError, exit code 9) before the pair stage — on both backends (CUDA
// cases skip without a GPU). The CLI prints a warning when the estimate is far above the usual.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <random>

#include "backends.hpp"
#include "engine.hpp"
#include "io/scene_file.hpp"
#include "scenes.hpp"
#include "support/run_cli.hpp"
#include "temp_dir.hpp"

namespace cg::test {
namespace {

template <class T>
class PairEstimateTest : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(T); }

  // One detection in fp64 with the limit `max_tests`; the estimates the engine handed out.
  Contacts<double> run(const Spheres& s, std::uint64_t max_tests, std::vector<PairEstimate>& seen,
                       EngineStats* stats = nullptr, BroadPhase broad = BroadPhase::automatic) {
    EngineOptions o;
    o.backend = T::backend;
    o.broad_phase = broad;
    o.max_pair_tests = max_tests;
    o.on_pair_estimate = [&seen](const PairEstimate& e) { seen.push_back(e); };
    Engine<double> engine(o);
    Contacts<double> c = engine.detect(BodiesView{s.p, s.r, {}, {}});
    if (stats) *stats = engine.stats();
    return c;
  }
};
TYPED_TEST_SUITE(PairEstimateTest, BackendTypes, BackendTypeNames);

// Random scenes: the estimate bounds the tests made, within the few cells a body spans, and is usual.
TYPED_TEST(PairEstimateTest, BoundsTheTestsOfRandomScenes) {
  for (std::uint64_t seed : {3u, 4u}) {
    for (const Spheres& s :
         {random_spheres(20000, 0.5, 0.5, seed), random_spheres(20000, 0.1, 1.0, seed + 10)}) {
      SCOPED_TRACE(s.name);
      std::vector<PairEstimate> seen;
      EngineStats stats;
      this->run(s, 0, seen, &stats);
      ASSERT_EQ(seen.size(), 1u);
      const PairEstimate& e = seen[0];
      EXPECT_EQ(e.bodies, s.r.size());
      EXPECT_EQ(e.entries, stats.entries);
      EXPECT_GE(e.tests, stats.pair_tests);
      EXPECT_LE(e.tests, 8 * stats.pair_tests + e.entries);
      EXPECT_GE(e.largest, 1u);
      EXPECT_FALSE(pair_work_unusual(e));
    }
  }
}

// Bodies stacked well inside one cell (one entry each): the estimate is exactly n·(n − 1)/2, the
// tests the pair stage makes; the fullest cell holds every body. A limit one below refuses the scene
// with LimitError naming the limit; the estimate itself as the limit passes.
TYPED_TEST(PairEstimateTest, StackedBodiesAreRefusedAboveTheLimit) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-0.01, 0.01);
  Spheres s;
  const std::size_t n = 1500;
  for (std::size_t i = 0; i < n; ++i) s.add(u(rng), u(rng), u(rng), 0.02);  // every pair touches
  s.add(10, 10, 10, 0.5);  // the cells are sized for this one, so the rest share one cell
  std::vector<PairEstimate> seen;
  EngineStats stats;
  const Contacts<double> c = this->run(s, 0, seen, &stats);
  ASSERT_EQ(seen.size(), 1u);
  EXPECT_EQ(seen[0].tests, std::uint64_t(n) * (n - 1) / 2);
  EXPECT_EQ(seen[0].tests, stats.pair_tests);
  EXPECT_EQ(seen[0].largest, n);
  EXPECT_EQ(c.size(), std::uint64_t(n) * (n - 1) / 2);

  seen.clear();
  try {
    this->run(s, std::uint64_t(n) * (n - 1) / 2 - 1, seen);
    ADD_FAILURE() << "a limit below the estimate should refuse the scene";
  } catch (const LimitError& e) {
    EXPECT_EQ(e.exit_code(), 9);
    EXPECT_NE(std::string(e.what()).find("--max-pair-tests " + std::to_string(n * (n - 1) / 2 - 1)),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("the fullest cell holds 1500 entries"), std::string::npos)
        << e.what();
  }
  seen.clear();
  EXPECT_EQ(this->run(s, std::uint64_t(n) * (n - 1) / 2, seen).size(), c.size());
}

// Every broad phase estimates its tests before its pair stage (grid and levels: Σ m·(m − 1)/2 over the
// cells of the sorted entries, the levels' within each level; sweep: the boxes each sweep passes;
// brute: every pair) and refuses the pile below the estimate; each estimate bounds the pile's pairs
// and the tests made (the levels' with the pairs across levels: the one large body against the pile).
TYPED_TEST(PairEstimateTest, EveryBroadPhaseEstimatesAndRefusesAPile) {
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> u(-0.01, 0.01);
  Spheres s;
  const std::uint64_t n = 1200, pairs = n * (n - 1) / 2;
  for (std::uint64_t i = 0; i < n; ++i) s.add(u(rng), u(rng), u(rng), 0.02);
  s.add(10, 10, 10, 0.5);
  for (const BroadPhase broad :
       {BroadPhase::grid, BroadPhase::levels, BroadPhase::sweep, BroadPhase::brute}) {
    SCOPED_TRACE(to_string(broad));
    std::vector<PairEstimate> seen;
    EngineStats stats;
    const Contacts<double> c = this->run(s, 0, seen, &stats, broad);
    EXPECT_EQ(stats.broad_phase, broad);
    ASSERT_EQ(seen.size(), 1u);
    EXPECT_EQ(c.size(), pairs);
    EXPECT_GE(seen[0].tests, pairs);
    EXPECT_GE(seen[0].tests, stats.pair_tests);
    EXPECT_GE(seen[0].largest, n - 1);
    EXPECT_GT(seen[0].tests_per_second, 0);
    try {
      seen.clear();
      this->run(s, pairs - 1, seen, nullptr, broad);
      ADD_FAILURE() << "a limit below the estimate should refuse the pile";
    } catch (const LimitError& e) {
      EXPECT_EQ(e.exit_code(), 9);
      EXPECT_NE(std::string(e.what()).find("--max-pair-tests " + std::to_string(pairs - 1)),
                std::string::npos)
          << e.what();
    }
  }
}

// Large bodies stacked on one point among many small grains: each pair of the pile is one test, but
// every grain in the pile's cell of the large bodies' level meets the whole pile there, so the levels'
// tests are the grains times the pile. Their estimate counts the pairs across levels (a bound from the
// cells' entries, before any is tested): it bounds the tests made, and a limit far above the pile's own
// pairs but below the grains' refuses the scene before its pair stage.
TYPED_TEST(PairEstimateTest, LevelsCountThePairsAcrossLevels) {
  const auto scene = [](std::uint64_t pile, std::uint64_t grains) {
    std::mt19937_64 rng(21);
    std::uniform_real_distribution<double> near(-0.01, 0.01), box(-0.45, 0.45);
    Spheres s;
    for (std::uint64_t i = 0; i < pile; ++i) s.add(0.5 + near(rng), 0.5 + near(rng), 0.5 + near(rng), 0.5);
    for (std::uint64_t i = 0; i < grains; ++i) s.add(0.5 + box(rng), 0.5 + box(rng), 0.5 + box(rng), 0.005);
    return s;
  };
  {  // small enough to run: the estimate bounds the tests, the tests include the grains against the pile
    const std::uint64_t pile = 30, grains = 3000;
    std::vector<PairEstimate> seen;
    EngineStats stats;
    const Contacts<double> c = this->run(scene(pile, grains), 0, seen, &stats, BroadPhase::levels);
    ASSERT_EQ(stats.broad_phase, BroadPhase::levels);
    ASSERT_EQ(seen.size(), 1u);
    EXPECT_GE(stats.pair_tests, pile * grains / 2);
    EXPECT_GE(seen[0].tests, stats.pair_tests);
    EXPECT_GE(c.size(), pile * (pile - 1) / 2);
  }
  const std::uint64_t pile = 400,
                      grains =
                          40000;  // 16e6 tests across levels; the pile its own 80e3 pairs in up to 8 cells
  std::vector<PairEstimate> seen;
  try {
    this->run(scene(pile, grains), 20 * pile * pile, seen, nullptr, BroadPhase::levels);
    ADD_FAILURE() << "the grains against the pile exceed the limit";
  } catch (const LimitError& e) {
    EXPECT_EQ(e.exit_code(), 9);
    EXPECT_NE(std::string(e.what()).find("--max-pair-tests " + std::to_string(20 * pile * pile)),
              std::string::npos)
        << e.what();
  }
  ASSERT_EQ(seen.size(), 1u);
  EXPECT_GE(seen[0].tests, pile * grains / 2);
}

// The host pair stage reports its progress whatever the estimate: the tests done so far, last the
// whole count, finished.
TEST(PairEstimate, HostPairStageReportsItsProgress) {
  const Spheres s = random_spheres(20000, 0.5, 0.5, 5);
  std::vector<std::pair<std::uint64_t, bool>> calls;
  EngineOptions o;
  o.backend = Backend::cpu;
  o.threads = 2;
  o.on_pair_progress = [&calls](std::uint64_t done, bool finished) { calls.emplace_back(done, finished); };
  Engine<double> engine(o);
  engine.detect(BodiesView{s.p, s.r, {}, {}});
  ASSERT_FALSE(calls.empty());
  EXPECT_TRUE(calls.back().second);
  EXPECT_EQ(calls.back().first, engine.stats().pair_tests);
  for (std::size_t k = 0; k + 1 < calls.size(); ++k) {
    EXPECT_FALSE(calls[k].second);
    EXPECT_LE(calls[k].first, calls.back().first);
  }
}

// A GPU grid pair stage far above the usual reports its progress while its kernel runs: 300 000
// bodies of radius 1e-4 in a unit cube, in one cell (the cells are sized for one body of radius 1 far
// away), 4.5e10 tests and next to no contacts. Calls come while the stage runs (the kernel takes about
// a second), never above the next, and last the tests made, finished. A usual scene reports nothing.
// (Brute force reports none: its tiles' bounding boxes skip most of the n(n - 1)/2 pairs it is
// estimated at, so its count of tests would not measure its way through them.) Skips visibly without
// a GPU.
TEST(PairEstimate, CudaPairStageReportsTheProgressOfLongWork) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device";
  const std::size_t n = 300000;
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Spheres s;
  for (std::size_t i = 0; i < n; ++i) s.add(u(rng), u(rng), u(rng), 1e-4);
  s.add(10, 10, 10, 1.0);
  {
    std::vector<std::pair<std::uint64_t, bool>> calls;
    std::vector<PairEstimate> seen;
    EngineOptions o;
    o.backend = Backend::cuda;
    o.broad_phase = BroadPhase::grid;
    o.on_pair_estimate = [&seen](const PairEstimate& e) { seen.push_back(e); };
    o.on_pair_progress = [&calls](std::uint64_t done, bool finished) { calls.emplace_back(done, finished); };
    Engine<double> engine(o);
    engine.detect(BodiesView{s.p, s.r, {}, {}});
    ASSERT_EQ(seen.size(), 1u);
    EXPECT_TRUE(pair_work_unusual(seen[0]));
    EXPECT_EQ(seen[0].largest, n);
    ASSERT_GE(calls.size(), 2u) << "no report while the pair stage ran";
    EXPECT_TRUE(calls.back().second);
    EXPECT_EQ(calls.back().first, engine.stats().pair_tests);
    EXPECT_GT(calls.back().first, std::uint64_t(n) * (n - 1) / 4);
    for (std::size_t k = 0; k + 1 < calls.size(); ++k) {
      EXPECT_FALSE(calls[k].second);
      EXPECT_LE(calls[k].first, calls[k + 1].first);
    }
  }
  // a usual scene: no progress from the GPU
  const Spheres usual = random_spheres(20000, 0.5, 0.5, 5);
  std::vector<std::pair<std::uint64_t, bool>> calls;
  EngineOptions o;
  o.backend = Backend::cuda;
  o.on_pair_progress = [&calls](std::uint64_t done, bool finished) { calls.emplace_back(done, finished); };
  Engine<double> engine(o);
  engine.detect(BodiesView{usual.p, usual.r, {}, {}});
  EXPECT_TRUE(calls.empty());
}

// One scene, both backends: the same estimate (the cells' entries are the same on both). Skips
// visibly without a GPU.
TEST(PairEstimate, SameOnCpuAndCuda) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device";
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-0.2, 0.2);
  Spheres s = random_spheres(30000, 0.1, 1.0, 12);
  for (int i = 0; i < 3000; ++i) s.add(u(rng), u(rng), u(rng), 0.01);  // a crowded corner
  for (const BroadPhase broad : {BroadPhase::grid, BroadPhase::levels}) {
    SCOPED_TRACE(to_string(broad));
    PairEstimate on[2];
    int k = 0;
    for (const Backend backend : {Backend::cpu, Backend::cuda}) {
      EngineOptions o;
      o.backend = backend;
      o.broad_phase = broad;
      o.on_pair_estimate = [&on, k](const PairEstimate& e) { on[k] = e; };
      Engine<double> engine(o);
      engine.detect(BodiesView{s.p, s.r, {}, {}});
      ++k;
    }
    EXPECT_EQ(on[0].tests, on[1].tests);
    EXPECT_EQ(on[0].entries, on[1].entries);
    EXPECT_EQ(on[0].largest, on[1].largest);
    EXPECT_EQ(on[0].bodies, on[1].bodies);
    EXPECT_GT(on[0].tests_per_second, 0);
    EXPECT_GT(on[1].tests_per_second, 0);
  }
}

TEST(PairEstimate, UnusualMeansSecondsOfWorkAndThousandsPerBody) {
  EXPECT_FALSE(pair_work_unusual({999'999'999, 1000, 1000, 1000}));
  EXPECT_FALSE(pair_work_unusual({2'000'000'000, 4'000'000, 8'000'000, 100}));  // 500 per body
  EXPECT_TRUE(pair_work_unusual({2'000'000'000, 1'000'000, 1'000'000, 60'000}));
  EXPECT_EQ(describe({500'000'000'000, 1'000'000, 1'000'000, 1'000'000}),
            "about 5e+11 pair tests (5e+05 per body; the fullest cell holds 1000000 entries)");
  EXPECT_EQ(
      describe({4'000'000'000, 1'000'000, 1'000'000, 60'000, 2e8}),
      "about 4e+09 pair tests (4e+03 per body; the fullest cell holds 60000 entries; about 20 s at 2e+08 "
      "tests a second)");
  EXPECT_EQ(describe_seconds(30), "30 s");
  EXPECT_EQ(describe_seconds(600), "10 min");
  EXPECT_EQ(describe_seconds(3 * 3600), "3 h");
  EXPECT_EQ(describe_seconds(5 * 86400), "5 days");
}

class PairLimitCli : public TempDirTest {};

// End to end: a scene whose bodies pile into one cell is refused by --max-pair-tests (exit 9, one
// message, no output), after the warning that the pair stage would be far above the usual.
TEST_F(PairLimitCli, RefusesAPileWithExitCode9AndWarnsFirst) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-0.01, 0.01);
  Scene scene;
  for (int i = 0; i < 60000; ++i) {
    scene.sphere_position.push_back({u(rng), u(rng), u(rng)});
    scene.sphere_radius.push_back(0.001);
  }
  scene.sphere_position.push_back({10, 10, 10});
  scene.sphere_radius.push_back(0.5);
  write_scene(path("pile.h5"), scene);
  const CliResult r = run_cli("detect " + path("pile.h5") + " -o " + path("out.h5") +
                              " --backend cpu --max-pair-tests 1000000");
  EXPECT_EQ(r.code, 9) << r.output;
  EXPECT_NE(r.output.find("warning: the pair stage will make about 1.8e+09 pair tests"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("more than --max-pair-tests 1000000"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("tests a second)"), std::string::npos) << "no time estimate: " << r.output;
  EXPECT_FALSE(std::filesystem::exists(path("out.h5")));
  for (const auto& name : entries()) EXPECT_EQ(name, "pile.h5") << "left behind: " << name;
}

// Coincident bodies (every centre the same point): refused before the pair stage with the count and
// the time it would take, in seconds of wall time. The bound is no performance figure: the pair
// stage of this scene (2e9 tests or more, every one a contact) would run for minutes and need hundreds of GB,
// so a refusal within it shows the refusal came first.
TEST_F(PairLimitCli, RefusesCoincidentBodiesQuickly) {
  Scene scene;
  for (int i = 0; i < 64000; ++i) {
    scene.sphere_position.push_back({1, 2, 3});
    scene.sphere_radius.push_back(0.5);
  }
  write_scene(path("same.h5"), scene);
  const auto start = std::chrono::steady_clock::now();
  const CliResult r = run_cli("detect " + path("same.h5") + " -o " + path("out.h5") +
                              " --backend cpu --threads 2 --max-pair-tests 100000000");
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(r.code, 9) << r.output;
  EXPECT_NE(r.output.find("error: the pair stage would make about "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("the fullest cell holds 64000 entries; about "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("more than --max-pair-tests 100000000"), std::string::npos) << r.output;
  EXPECT_LT(seconds, 60) << r.output;
  EXPECT_FALSE(std::filesystem::exists(path("out.h5")));
}

}  // namespace
}  // namespace cg::test
