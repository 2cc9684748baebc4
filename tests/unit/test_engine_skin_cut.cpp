// A skin's list cut by the centre line (core/centre_cut.hpp, scenes of at least 4 ellipsoids in 5): one
// test body over both backends and precisions (CUDA cases skip, visibly, without a GPU). Every call
// equals a fresh skin-0 detection of the same bodies, bit for bit; the kept list is smaller than the
// inflated bounding spheres' (CONTACTGRID_SKIN_CUT=0, counted by brute force) while the bodies do not
// turn, and once a check has seen them turn every build keeps the bounding spheres (core/skin.hpp:
// skin_cut_wanted); a turn alone, without any translation, must rebuild before the pair it brings
// together touches; a change of semi-axes rebuilds.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "backends.hpp"
#include "engine.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"
#include "support/scoped_env.hpp"

namespace cg::test {
namespace {

using Env = ScopedEnv;  // (support/scoped_env.hpp)

template <class Cfg>
class EngineSkinCutTest : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(Cfg); }
};
TYPED_TEST_SUITE(EngineSkinCutTest, AllConfigs, ConfigNames);

EngineOptions options_for(Backend backend, double skin) {
  EngineOptions o;
  o.backend = backend;
  o.skin = skin;
  o.fields = Fields::full;  // every field compared
  return o;
}

// "identical" when `got` holds `want`'s rows, all of them; else the two counts, or compare_contacts'
// differing fields.
template <class Real>
std::string same_rows(const Contacts<Real>& got, const Contacts<Real>& want) {
  if (got.size() != want.size())
    return "rows " + std::to_string(got.size()) + " against " + std::to_string(want.size());
  return compare_contacts(got, want);
}

Quat<double> about_z(double angle) { return {std::cos(angle / 2), 0, 0, std::sin(angle / 2)}; }

// The pairs whose bounding spheres, each inflated by skin/2, come within `slack` of touching.
std::uint64_t inflated_overlaps(const ShapeScene& s, double skin, double slack) {
  std::uint64_t n = 0;
  for (std::size_t a = 0; a < s.p.size(); ++a)
    for (std::size_t b = a + 1; b < s.p.size(); ++b) {
      const Vec3<double> d = s.p[a] - s.p[b];
      n += std::sqrt(dot(d, d)) <= s.r[a] + s.r[b] + skin + slack;
    }
  return n;
}

// Ellipsoids that move over many calls, then move and turn: every call equals a fresh detection (and,
// on the device, the CPU backend's rows and kept list). While they only move, each build's cut list
// is smaller than the former one (the same calls under CONTACTGRID_SKIN_CUT=0, also equal to the fresh
// rows) and at least the fresh call's centre-cut candidates; once they turn, a check of the cut list
// sees the turn as motion and the builds after it keep the former list (the same count as the knob's).
TYPED_TEST(EngineSkinCutTest, TurningEllipsoidsEqualFreshDetection) {
  using Real = typename TypeParam::Real;
  const double skin = 0.12;
  Engine<Real> cut(options_for(TypeParam::backend, skin)), old(options_for(TypeParam::backend, skin));
  Engine<Real> fresh(options_for(TypeParam::backend, 0));
  Engine<Real> host(options_for(Backend::cpu, skin));  // the CPU backend's kept list, for the device
  ShapeScene s = make_scene("skin cut", 9171, 1200, 1.0, 12.0);
  std::mt19937_64 rng(9172);
  std::uniform_real_distribution<double> u(-1, 1);
  std::uint64_t compared = 0, compared_turning = 0;
  bool turned = false;  // a check of the cut list has seen the bodies turn
  for (int call = 0; call < 30; ++call) {
    const bool turns = call >= 15;  // the bodies turn from call 15 on (their motion at the end of a call)
    const std::string at = s.name + " call " + std::to_string(call);
    const std::uint64_t cut_builds = cut.stats().candidate_builds;
    const std::uint64_t old_builds = old.stats().candidate_builds;
    const Contacts<Real> got = cut.detect(s.view());
    const EngineStats st = cut.stats();
    Contacts<Real> former;
    {
      Env knob("CONTACTGRID_SKIN_CUT", "0");
      former = old.detect(s.view());
    }
    const Contacts<Real> want = fresh.detect(s.view());
    ASSERT_EQ(same_rows(got, want), "identical") << at;
    ASSERT_EQ(same_rows(former, want), "identical") << at << " (CONTACTGRID_SKIN_CUT=0)";
    EXPECT_EQ(st.narrow_unconverged, fresh.stats().narrow_unconverged) << at;
    EXPECT_GT(got.size(), 100u) << at;
    EXPECT_GE(st.candidates, fresh.stats().candidates) << at << ": a skin keeps at least the fresh cut's";
    if (TypeParam::backend == Backend::cuda) {  // CPU = CUDA: the rows and the kept list
      const Contacts<Real> on_host = host.detect(s.view());
      ASSERT_EQ(same_rows(got, on_host), "identical") << at;
      EXPECT_EQ(st.candidates, host.stats().candidates) << at;
      EXPECT_EQ(st.candidate_builds, host.stats().candidate_builds) << at;
      EXPECT_EQ(st.skin_displacement, host.stats().skin_displacement) << at;
    }
    if (turns && call > 15 && !turned) {  // the first check after a turn: a cut list's, it sees it
      EXPECT_GT(st.skin_displacement, old.stats().skin_displacement) << at << ": a turn is motion";
      turned = true;
    }
    if (!turned && st.candidate_builds > cut_builds && old.stats().candidate_builds > old_builds) {
      ++compared;  // both built from these bodies: the cut list is the smaller
      EXPECT_LT(st.candidates, old.stats().candidates) << at;
      EXPECT_LT(2 * st.candidates, old.stats().candidates + fresh.stats().candidates) << at;
    }
    if (turned && st.candidate_builds > cut_builds) {  // the bodies turn: the bounding spheres' list
      ++compared_turning;
      Engine<Real> knob_off(options_for(TypeParam::backend, skin));
      Env knob("CONTACTGRID_SKIN_CUT", "0");
      knob_off.detect(s.view());
      EXPECT_EQ(st.candidates, knob_off.stats().candidates) << at;
    }
    if (call > 0 && st.candidate_builds > cut_builds) {  // the check saw more than the skin allows
      EXPECT_GT(2 * (st.skin_displacement + st.skin_growth), skin) << at;
    }
    for (std::size_t i = 0; i < s.p.size(); ++i) {
      const double step = turns ? 0.004 : 0.012;  // (unturned: a few builds in 15 calls)
      s.p[i] = s.p[i] + Vec3<double>{step * u(rng), step * u(rng), step * u(rng)};
      if (!turns) continue;
      Quat<double>& q = s.q[i];  // a small turn, renormalised
      q = {q.w + 0.006 * u(rng), q.x + 0.006 * u(rng), q.y + 0.006 * u(rng), q.z + 0.006 * u(rng)};
      const double k = 1 / std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
      q = {q.w * k, q.x * k, q.y * k, q.z * k};
    }
  }
  EXPECT_GE(compared, 2u);
  EXPECT_GE(compared_turning, 1u);
  EXPECT_GE(cut.stats().candidate_reuses, 10u);
  // turning alone: the check of a cut list sees it (a fresh engine: the check measures from its build)
  Engine<Real> turning(options_for(TypeParam::backend, skin));
  turning.detect(s.view());
  for (auto& q : s.q) {
    const double k = 1 / std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + (q.z + 0.01) * (q.z + 0.01));
    q = {q.w * k, q.x * k, q.y * k, (q.z + 0.01) * k};
  }
  const Contacts<Real> got = turning.detect(s.view());
  EXPECT_GT(turning.stats().skin_displacement, 0.0);
  EXPECT_EQ(same_rows(got, fresh.detect(s.view())), "identical");
}

// A scene of the cut with spheres in it (9 ellipsoids in 10: sphere and sphere–ellipsoid pairs stay
// uncut): bodies move (without turning: the list stays cut), spheres grow, now and then an ellipsoid's
// smaller semi-axes change (its bounding radius kept: no growth); every call equals a fresh
// detection, and on the device the CPU's.
TYPED_TEST(EngineSkinCutTest, MixedSceneOfTheCutEqualsFreshDetection) {
  using Real = typename TypeParam::Real;
  const double skin = 0.1;
  Engine<Real> engine(options_for(TypeParam::backend, skin)), fresh(options_for(TypeParam::backend, 0));
  Engine<Real> host(options_for(Backend::cpu, skin));
  ShapeScene s = make_scene("skin cut mixed", 9175, 900, 0.9, 11.0);
  std::mt19937_64 rng(9176);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int call = 0; call < 16; ++call) {
    const std::string at = s.name + " call " + std::to_string(call);
    const Contacts<Real> got = engine.detect(s.view());
    ASSERT_EQ(same_rows(got, fresh.detect(s.view())), "identical") << at;
    if (TypeParam::backend == Backend::cuda) {
      ASSERT_EQ(same_rows(got, host.detect(s.view())), "identical") << at;
      EXPECT_EQ(engine.stats().candidates, host.stats().candidates) << at;
    }
    for (std::size_t i = 0; i < s.p.size(); ++i) {
      s.p[i] = s.p[i] + Vec3<double>{0.003 * u(rng), 0.003 * u(rng), 0.003 * u(rng)};
      if (s.shape[i] == Shape::sphere) {
        s.r[i] += 0.002 * (u(rng) + 1);
        continue;
      }
      if (call % 5 == 4 && i % 50 == 0) {  // the smallest semi-axis grows by a tenth at most
        Vec3<double>& e = s.axes[i];
        double& least = e.x <= e.y && e.x <= e.z ? e.x : (e.y <= e.z ? e.y : e.z);
        least = std::min(s.r[i], 1.1 * least);
      }
    }
  }
  EXPECT_GE(engine.stats().candidate_reuses, 4u);
  EXPECT_GE(engine.stats().candidate_builds, 4u) << "the semi-axes' changes rebuild";
}

// CONTACTGRID_SKIN_CUT=0: a build keeps every pair of inflated bounding spheres (the former list,
// counted here by brute force up to the inflation's rounding margin, < 10^-4); the cut keeps fewer,
// the same rows.
TYPED_TEST(EngineSkinCutTest, KnobOffKeepsTheBoundingSpheres) {
  using Real = typename TypeParam::Real;
  const double skin = 0.15;
  const ShapeScene s = make_scene("skin cut knob", 9173, 900, 1.0, 11.0);
  Engine<Real> fresh(options_for(TypeParam::backend, 0));
  const Contacts<Real> want = fresh.detect(s.view());
  Engine<Real> old(options_for(TypeParam::backend, skin)), cut(options_for(TypeParam::backend, skin));
  {
    Env knob("CONTACTGRID_SKIN_CUT", "0");
    ASSERT_EQ(same_rows(old.detect(s.view()), want), "identical");
  }
  ASSERT_EQ(same_rows(cut.detect(s.view()), want), "identical");
  const std::uint64_t lo = inflated_overlaps(s, skin, 0), hi = inflated_overlaps(s, skin, 1e-4);
  ASSERT_LE(hi, lo + 3) << "the band of the margin holds a few pairs at most";
  EXPECT_GE(old.stats().candidates, lo);
  EXPECT_LE(old.stats().candidates, hi);
  EXPECT_LT(cut.stats().candidates, lo);
  EXPECT_GE(cut.stats().candidates, fresh.stats().candidates);
}

// The needles of the two tests below: A along x at the origin, B across it (along y) at x = 2.45.
ShapeScene needles() {
  const double pi = std::acos(-1.0);
  ShapeScene s;
  s.name = "needles";
  s.p = {{0, 0, 0}, {2.45, 0, 0}};
  s.r = {2, 2};
  s.shape = {Shape::ellipsoid, Shape::ellipsoid};
  s.axes = {{2, 0.2, 0.2}, {2, 0.2, 0.2}};
  s.q = {about_z(0), about_z(pi / 2)};
  return s;
}

// Two needles (semi-axes 2, 0.2, 0.2): A along x at the origin, B across it (along y) at x = 2.45,
// apart along the centre line by 0.25, a bit more than the skin 0.2: the cut drops the pair at the
// build (its bounding spheres overlap: the former list keeps it). Then B turns about z, a degree a
// call, no translation, until it lies nearly along A and overlaps it: the check must see the turn and
// rebuild (a check of the translation alone keeps the empty list for ever), into the bounding spheres'
// list (the bodies turn: core/skin.hpp), so the contact appears at the call where a fresh detection
// finds it.
TYPED_TEST(EngineSkinCutTest, ATurnAloneRebuildsBeforeTheContact) {
  using Real = typename TypeParam::Real;
  const double skin = 0.2, pi = std::acos(-1.0);
  ShapeScene s = needles();
  Engine<Real> engine(options_for(TypeParam::backend, skin)), fresh(options_for(TypeParam::backend, 0));
  Engine<Real> old(options_for(TypeParam::backend, skin));
  int first_contact = -1;
  for (int call = 0; call <= 90; ++call) {
    const std::string at = "call " + std::to_string(call);
    s.q[1] = about_z(pi / 2 - call * pi / 180);
    const std::uint64_t builds = engine.stats().candidate_builds;
    const Contacts<Real> got = engine.detect(s.view());
    const Contacts<Real> want = fresh.detect(s.view());
    ASSERT_EQ(same_rows(got, want), "identical") << at;
    if (call == 0) {
      EXPECT_EQ(engine.stats().candidates, 0u) << "the cut drops the pair apart by more than the skin";
      Env knob("CONTACTGRID_SKIN_CUT", "0");
      old.detect(s.view());
      EXPECT_EQ(old.stats().candidates, 1u) << "the former list keeps its bounding spheres' overlap";
    } else if (engine.stats().candidate_builds == 1) {  // a reuse of the cut list: the turn within the skin
      EXPECT_LE(2 * engine.stats().skin_displacement, skin) << at;
      EXPECT_GT(engine.stats().skin_displacement, 0.0) << at << ": a turn is motion";
    } else if (engine.stats().candidate_builds > builds) {  // the turn's rebuild: the bounding spheres
      EXPECT_GT(2 * engine.stats().skin_displacement, skin) << at;
      EXPECT_EQ(engine.stats().candidates, 1u) << at;
    }
    if (first_contact < 0 && want.size() > 0) first_contact = call;
  }
  ASSERT_GT(first_contact, 5) << "the pair touches only after a few turns";
  ASSERT_LT(first_contact, 90);
  EXPECT_EQ(engine.stats().candidate_builds, 2u) << "a turn alone rebuilt the cut list, once";
}

// A change of a body's semi-axes that keeps its bounding radius (no growth, no motion) rebuilds a
// cut list: B of the needles above, across A, widened along the centre line until it overlaps A.
TYPED_TEST(EngineSkinCutTest, ChangedSemiAxesRebuild) {
  using Real = typename TypeParam::Real;
  const double skin = 0.2;
  ShapeScene s = needles();
  Engine<Real> engine(options_for(TypeParam::backend, skin)), fresh(options_for(TypeParam::backend, 0));
  ASSERT_EQ(engine.detect(s.view()).size(), 0u);
  ASSERT_EQ(engine.stats().candidate_builds, 1u);
  engine.detect(s.view());  // the same bodies: a reuse
  EXPECT_EQ(engine.stats().candidate_reuses, 1u);
  s.axes[1] = {2, 1, 0.2};  // B's local y (world −x) reaches 1 towards A: they overlap
  const Contacts<Real> got = engine.detect(s.view());
  EXPECT_EQ(engine.stats().candidate_builds, 2u) << "semi-axes changed: rebuilt";
  EXPECT_EQ(engine.stats().skin_growth, 0.0);
  const Contacts<Real> want = fresh.detect(s.view());
  ASSERT_EQ(want.size(), 1u);
  EXPECT_EQ(same_rows(got, want), "identical");
}

}  // namespace
}  // namespace cg::test
