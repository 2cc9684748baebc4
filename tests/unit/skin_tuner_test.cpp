// The automatic skin (kernels/skin_tuner.hpp) against a modelled cost, and the engine's skin changes
// (Engine::set_skin, EngineOptions::skin_auto): contacts a skin-0 detection's bit for bit.
#include "skin_tuner.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "backends.hpp"
#include "engine.hpp"
#include "step_bodies.hpp"
#include "support/contacts_equal.hpp"

namespace cg {
namespace {

// Steps of bodies moving `v` per step under a modelled cost: a build costs build(s), a reuse
// reuse(s); a list lasts while the displacement since its build is <= s/2. Returns the tuner's
// final choice of reuses per build, the builds made and the mean cost per step over the last 200 steps.
struct TunedRun {
  int n = 0, builds = 0;
  double skin = 0, mean = 0;
};
template <class Build, class Reuse>
TunedRun simulate(double v, int steps, Build&& build, Reuse&& reuse, double length = 1) {
  SkinTuner tuner(length);
  double kept_skin = 0, moved = 0;
  int since = 0;
  bool kept = false;
  double tail_cost = 0;
  int tail = 0, builds = 0;
  for (int k = 0; k < steps; ++k) {
    const double skin = tuner.skin();
    moved += v;
    ++since;
    const bool reused = kept && kept_skin > 0 && 2 * moved <= kept_skin;
    const double cost = reused ? reuse(kept_skin) : build(skin);
    tuner.observe(!reused, cost, kept ? moved : 0, since);
    if (!reused) {
      ++builds;
      kept = skin > 0;
      kept_skin = skin;
      moved = 0;
      since = 0;
    }
    if (k >= steps - 200) tail_cost += cost, ++tail;
  }
  return {tuner.reuses_per_build(), builds, tuner.skin(), tail_cost / std::max(tail, 1)};
}

// Costs rising with the skin (more candidates): the tuner's lines through the measured builds and
// reuses find the n of the lowest (build + n·reuse)/(n + 1), and it gets there within a few cycles.
TEST(SkinTuner, FindsTheCheapestReusesPerBuild) {
  const double v = 0.01;
  auto build = [](double s) { return 10.0 * (1 + 4 * s); };
  auto reuse = [](double s) { return 1.0 * (1 + 4 * s); };
  auto mean_of = [&](int n) {
    const double s = 2 * v * n * (1 + 1.0 / 16);
    return (build(s) + n * reuse(s)) / (n + 1);
  };
  double best = 1e300;
  int best_n = 0;
  for (int n = 1; n <= 256; ++n)
    if (mean_of(n) < best) best = mean_of(n), best_n = n;
  const TunedRun r = simulate(v, 2000, build, reuse);
  EXPECT_EQ(r.n, best_n);
  EXPECT_NEAR(r.skin, 2 * v * best_n * (1 + 1.0 / 16), 1e-12);
  EXPECT_LT(r.mean, 1.01 * best);
  EXPECT_LT(r.mean, 0.5 * build(0));  // far cheaper than building every step
  // the search: n = 2, then 8, then the model's choice — the first 40 steps hold at most 8 builds
  // (three of them before the motion is known; a doubling search by measured means made 11)
  const int builds = simulate(v, 40, build, reuse).builds;
  EXPECT_LE(builds, 8);
}

// A cheaper reuse (or a dearer build) moves the choice to longer lists: the model follows the costs.
TEST(SkinTuner, CheaperReusesChooseLongerLists) {
  auto run = [](double reuse_cost) {
    return simulate(
               0.01, 600, [](double s) { return 10.0 * (1 + 4 * s); },
               [&](double s) { return reuse_cost * (1 + 8 * s); })
        .n;
  };
  EXPECT_GT(run(0.3), run(1.0));
}

// Free reuses: the search goes on doubling until the skin reaches twice the length scale.
TEST(SkinTuner, StopsAtTwiceTheLength) {
  const TunedRun r = simulate(
      0.01, 3000, [](double) { return 10.0; }, [](double) { return 0.0; }, 0.5);
  EXPECT_LE(r.skin, 2 * 0.5);
  EXPECT_GE(r.n, 32);
}

// Bodies that never move: a small skin, every call after the first reuses.
TEST(SkinTuner, StillBodiesKeepTheirList) {
  SkinTuner t(2.0);
  EXPECT_EQ(t.skin(), 0);  // nothing seen yet: from scratch
  t.observe(true, 1.0, 0, 1);
  EXPECT_EQ(t.skin(), 2.0 / 64);
  t.observe(true, 1.0, 0, 1);
  EXPECT_EQ(t.skin(), 2.0 / 64);
  EXPECT_EQ(t.speed(), 0);
}

// A faster motion shortens the lists at once: the skin follows the largest speed seen.
TEST(SkinTuner, FollowsTheLargestSpeed) {
  SkinTuner t(10.0);
  t.observe(true, 1, 0, 1);
  (void)t.skin();
  t.observe(false, 1, 0.1, 1);
  EXPECT_NEAR(t.skin(), 2 * 0.1 * 2 * (1 + 1.0 / 16), 1e-12);  // the first trial, n = 2
  t.observe(true, 1, 0.9, 3);                                  // 0.3 per step
  EXPECT_DOUBLE_EQ(t.speed(), 0.3);
  const double skin = t.skin();  // the search's next trial: 4 times the reuses the cycle made
  EXPECT_EQ(t.reuses_per_build(), 4);
  EXPECT_NEAR(skin, 2 * 0.3 * 4 * (1 + 1.0 / 16), 1e-12);
}

// Random spheres drifting by the CLI's rule.
struct Drifting {
  HostVector<Vec3<double>> p0;
  HostVector<double> r;
  HostVector<Vec3<double>> at(int step, double drift) const {
    HostVector<Vec3<double>> p(p0.size());
    for (std::size_t i = 0; i < p.size(); ++i) p[i] = drifted_position(std::int64_t(i), p0[i], drift, step);
    return p;
  }
};
Drifting drifting(std::size_t n, unsigned seed, double edge = 12) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> x(0, edge), r(0.3, 0.6);
  Drifting d;
  for (std::size_t i = 0; i < n; ++i) {
    d.p0.push_back({x(rng), x(rng), x(rng)});
    d.r.push_back(r(rng));
  }
  return d;
}

// An engine whose skin changes between calls (set_skin) or is chosen (skin_auto) gives a skin-0
// detection's contacts at every call, host bodies or resident ones, and reuses its lists.
template <class C>
class EngineSkin : public ::testing::Test {};
TYPED_TEST_SUITE(EngineSkin, test::AllConfigs, test::ConfigNames);

TYPED_TEST(EngineSkin, SetSkinAndAutoGiveTheContactsOfSkinZero) {
  using Real = typename TypeParam::Real;
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  const Drifting d = drifting(1500, 7);
  EngineOptions fresh;
  fresh.backend = TypeParam::backend;
  fresh.threads = 2;
  fresh.fields = Fields::full;
  EngineOptions automatic = fresh;
  automatic.skin_auto = true;
  EngineOptions fixed = fresh;
  fixed.skin = 0.08;
  Engine<Real> scratch(fresh), tuned(automatic), changed(fixed), resident(automatic);
  resident.set_resident(BodiesView{d.p0, d.r, {}, {}});
  for (int step = 0; step < 40; ++step) {
    const HostVector<Vec3<double>> p = d.at(step, 0.01);
    const BodiesView v{p, d.r, {}, {}};
    if (step == 15) changed.set_skin(0.3);  // the kept list keeps its own skin until the next build
    if (step == 30) changed.set_skin(0);    // no list from then on
    const Contacts<Real> want = scratch.detect(v);
    const Contacts<Real> a = tuned.detect(v), c = changed.detect(v);
    resident.write_resident(0, p.size(), p.data(), d.r.data());
    resident.detect_resident();
    const Contacts<Real>& r = resident.resident_contacts();
    for (const auto& [got, what] : {std::pair<const Contacts<Real>*, const char*>{&a, "auto"},
                                    {&c, "set_skin"},
                                    {&r, "resident auto"}}) {
      EXPECT_EQ(got->size(), want.size()) << what << ", step " << step;
      EXPECT_EQ(test::compare_contacts(*got, want), "identical") << what << ", step " << step;
    }
  }
  EXPECT_GT(tuned.stats().candidate_reuses, 12u);
  EXPECT_GT(tuned.stats().skin, 0);
  EXPECT_GT(resident.stats().candidate_reuses, 12u);
  EXPECT_GT(changed.stats().candidate_reuses, 5u);
  EXPECT_EQ(changed.stats().skin, 0);  // no list kept since set_skin(0)
  EXPECT_THROW(changed.set_skin(-1), UsageError);
  EXPECT_THROW(changed.set_skin(std::nan("")), UsageError);
}

// Resident steps with a skin over enough candidates for many tiles of the CUDA narrow's one-pass
// compaction (its decoupled look-back) and for the pair stage's direct write into the room the
// previous build left: every step a skin-0 detection's contacts, builds and reuses both seen.
TYPED_TEST(EngineSkin, ResidentStepsOverManyTilesGiveTheContactsOfSkinZero) {
  using Real = typename TypeParam::Real;
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  const std::size_t n = 40000;
  const Drifting d = drifting(n, 11, 12 * std::cbrt(double(n) / 1500));
  EngineOptions fresh;
  fresh.backend = TypeParam::backend;
  fresh.threads = 2;
  EngineOptions skinned = fresh;
  skinned.skin = 0.06;  // lasts two steps of 0.01 (2 · 0.02 <= 0.06), the third rebuilds
  Engine<Real> scratch(fresh), resident(skinned);
  resident.set_resident(BodiesView{d.p0, d.r, {}, {}});
  for (int step = 0; step < 7; ++step) {
    const HostVector<Vec3<double>> p = d.at(step, 0.01);
    const Contacts<Real> want = scratch.detect(BodiesView{p, d.r, {}, {}});
    resident.write_resident(0, p.size(), p.data(), d.r.data());
    resident.detect_resident();
    const Contacts<Real>& got = resident.resident_contacts();
    ASSERT_GT(want.size(), 20000u);
    EXPECT_EQ(test::compare_contacts(got, want), "identical") << "step " << step;
  }
  EXPECT_GE(resident.stats().candidate_reuses, 3u);
  EXPECT_GE(resident.stats().candidate_builds, 2u);
}

}  // namespace
}  // namespace cg
