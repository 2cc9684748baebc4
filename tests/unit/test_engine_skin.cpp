// Candidates kept across calls (EngineOptions::skin, a Verlet skin; kernels/core/skin.hpp), one test
// body over both backends and precisions (CUDA cases skip, visibly, without a GPU). The oracle of
// every call is a fresh skin-0 detection of the same bodies by a second engine: the same rows, bit
// for bit (the skin path packs in the same frame origin and decides with the same functions).
// Seeded random walks (host arrays with ids, resident bodies, device arrays), a step past skin/2
// (rebuild), a body count or report mask change (rebuild), pairs that close exactly the skin at its
// limit (dyadic coordinates: exact in fp32 and fp64), mixed sphere/ellipsoid scenes whose
// ellipsoids also turn and change shape between calls.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <random>
#include <string>
#include <type_traits>
#include <vector>

#include "backends.hpp"
#include "core/kept_room.hpp"
#include "engine.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"
#include "support/scoped_env.hpp"

#if defined(CONTACTGRID_HAVE_CUDA)
#include <cuda_runtime.h>
#endif

namespace cg::test {
namespace {

using Env = ScopedEnv;  // (support/scoped_env.hpp)

template <class Cfg>
class EngineSkinTest : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(Cfg); }
};
TYPED_TEST_SUITE(EngineSkinTest, AllConfigs, ConfigNames);

EngineOptions options_for(Backend backend, double skin) {
  EngineOptions o;
  o.backend = backend;
  o.skin = skin;
  o.fields = Fields::full;  // every field compared
  return o;
}

// The engine under test (with a skin) and its oracle (skin 0), on the configuration's backend.
template <class Cfg>
struct SkinEngines {
  explicit SkinEngines(double skin_)
      : kept(options_for(Cfg::backend, skin_)), fresh(options_for(Cfg::backend, 0)), skin(skin_) {}
  Engine<typename Cfg::Real> kept, fresh;
  const double skin;
};

std::vector<std::string> stage_names(const StageTimes& times) {
  std::vector<std::string> names;
  for (const StageTime& t : times) names.push_back(t.name);
  return names;
}

bool has_stage(const StageTimes& times, const std::string& name) {
  const std::vector<std::string> names = stage_names(times);
  return std::find(names.begin(), names.end(), name) != names.end();
}

// Every centre moved by a random vector of length <= step, every radius grown by up to `grow`
// (a few shrink: growth is what counts).
void random_step(Spheres& s, double step, double grow, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1), g(-0.5, 1);
  for (std::size_t i = 0; i < s.p.size(); ++i) {
    Vec3<double> d{u(rng), u(rng), u(rng)};
    const double len = std::sqrt(dot(d, d));
    if (len > 1) d = (1 / len) * d;
    s.p[i] = s.p[i] + step * d;
    s.r[i] = std::max(0.05, s.r[i] + grow * g(rng));
  }
}

// The bookkeeping of one call: a reuse exactly when the motion measured since the last build is
// within the skin, and the counters advance by one.
void expect_decision(const EngineStats& st, std::uint64_t calls_before, const std::string& at) {
  EXPECT_EQ(st.candidate_builds + st.candidate_reuses, calls_before + 1) << at;
  EXPECT_GE(st.candidates, st.contacts) << at;
}

// A random walk of `calls` detections through detect() (host arrays, ids 3i + 7): every call equals
// a fresh skin-0 detection; small steps reuse, the rebuilds come when the motion passes skin/2.
TYPED_TEST(EngineSkinTest, RandomWalkEqualsFreshDetection) {
  using Real = typename TypeParam::Real;
  SkinEngines<TypeParam> engines(0.2);
  auto& [engine, fresh, skin] = engines;
  Spheres s = random_spheres(4000, 0.4, 1.0, 9101);
  std::vector<std::int64_t> id(s.r.size());
  for (std::size_t i = 0; i < id.size(); ++i) id[i] = 3 * std::int64_t(i) + 7;
  std::mt19937_64 rng(9102);
  std::uint64_t rebuilds_seen = 0;
  for (int call = 0; call < 40; ++call) {
    const std::string at = "call " + std::to_string(call);
    const BodiesView v{s.p, s.r, id, {}};
    const std::uint64_t before = engine.stats().candidate_builds + engine.stats().candidate_reuses;
    const std::uint64_t builds_before = engine.stats().candidate_builds;
    const Contacts<Real> got = engine.detect(v);
    const Contacts<Real> want = fresh.detect(v);
    ASSERT_EQ(compare_contacts(got, want), "identical") << at;
    const EngineStats& st = engine.stats();
    expect_decision(st, before, at);
    const bool rebuilt = st.candidate_builds > builds_before;
    if (call > 0 && rebuilt) {
      ++rebuilds_seen;  // the check measured motion past the skin
      EXPECT_GT(2 * (st.skin_displacement + st.skin_growth), skin) << at;
    }
    if (call > 0 && !rebuilt) {
      EXPECT_LE(2 * (st.skin_displacement + st.skin_growth), skin) << at;
      EXPECT_EQ(stage_names(engine.times()).size(), TypeParam::backend == Backend::cuda ? 6u : 4u)
          << at << ": plan, (upload,) skin, pack, narrow(, download)";
      EXPECT_EQ(st.entries, 0u) << at << ": the reuse walks no grid";
    }
    EXPECT_GT(got.size(), 200u) << at;
    random_step(s, 0.012, 0.002, rng);
  }
  EXPECT_EQ(engine.stats().candidate_builds, 1 + rebuilds_seen);
  EXPECT_GE(rebuilds_seen, 2u) << "the walk passes skin/2 several times";
  EXPECT_GE(engine.stats().candidate_reuses, 25u) << "most calls reuse";
}

// The resident bodies (the simulation loop: write_resident + detect_resident) with a report mask.
TYPED_TEST(EngineSkinTest, ResidentStepsEqualFreshDetection) {
  using Real = typename TypeParam::Real;
  SkinEngines<TypeParam> engines(0.15);
  auto& [engine, fresh, skin] = engines;
  Spheres s = random_spheres(3000, 0.5, 1.0, 9111);
  std::mt19937_64 rng(9112);
  std::vector<std::uint8_t> report(s.r.size());
  for (auto& m : report) m = static_cast<std::uint8_t>(rng() % 4);  // every combination of the bits
  engine.set_resident(BodiesView{s.p, s.r, {}, report});
  for (int call = 0; call < 25; ++call) {
    const std::string at = "step " + std::to_string(call);
    if (call > 0) {
      random_step(s, 0.01, 0.0, rng);
      engine.write_resident(0, s.r.size(), s.p.data(), s.r.data());
    }
    const std::size_t k = engine.detect_resident();
    const Contacts<Real> want = fresh.detect(BodiesView{s.p, s.r, {}, report});
    ASSERT_EQ(k, want.size()) << at;
    ASSERT_EQ(compare_contacts(engine.resident_contacts(), want), "identical") << at;
  }
  EXPECT_GE(engine.stats().candidate_builds, 2u);
  EXPECT_GE(engine.stats().candidate_reuses, 15u);
}

// Precision::mixed (Engine<double> with an fp32 broad phase): the kept list is built by the float
// pair stage (its enlarged spheres plus the skin's inflation, whose margin is float's); every call
// equals a fresh mixed detection (= fp64's contacts). Engine<float> has no mixed mode: skipped.
TYPED_TEST(EngineSkinTest, MixedPrecisionWalkEqualsFreshDetection) {
  if constexpr (!std::is_same_v<typename TypeParam::Real, double>) {
    GTEST_SKIP() << "precision mixed is a mode of Engine<double>";
  } else {
    EngineOptions with = options_for(TypeParam::backend, 0.2), without = options_for(TypeParam::backend, 0);
    with.fp32_broad_phase = without.fp32_broad_phase = true;
    Engine<double> engine(with), fresh(without);
    Spheres s = random_spheres(3000, 0.5, 1.0, 9181).translated({1e4, -2e4, 3e3});
    std::mt19937_64 rng(9182);
    for (int call = 0; call < 20; ++call) {
      const Contacts<double> got = engine.detect(BodiesView{s.p, s.r, {}, {}});
      ASSERT_EQ(compare_contacts(got, fresh.detect(BodiesView{s.p, s.r, {}, {}})), "identical")
          << "call " << call;
      random_step(s, 0.012, 0.001, rng);
    }
    EXPECT_GE(engine.stats().candidate_builds, 2u);
    EXPECT_GE(engine.stats().candidate_reuses, 10u);
  }
}

// One body moved by just more than skin/2 forces a rebuild; by exactly skin/2 (a dyadic step on
// dyadic coordinates: the displacement is exact) the list is kept. Every call equals a fresh one.
TYPED_TEST(EngineSkinTest, StepPastHalfSkinRebuilds) {
  using Real = typename TypeParam::Real;
  SkinEngines<TypeParam> engines(0.25);
  auto& [engine, fresh, skin] = engines;
  Spheres s = random_spheres(2000, 0.5, 1.0, 9121);
  for (auto& p : s.p) p = {std::round(p.x * 64) / 64, std::round(p.y * 64) / 64, std::round(p.z * 64) / 64};
  for (auto& r : s.r) r = std::round(r * 64) / 64;  // dyadic: every step and growth below is exact
  auto call = [&](const std::string& at) {
    const Contacts<Real> got = engine.detect(BodiesView{s.p, s.r, {}, {}});
    ASSERT_EQ(compare_contacts(got, fresh.detect(BodiesView{s.p, s.r, {}, {}})), "identical") << at;
  };
  call("build");
  ASSERT_EQ(engine.stats().candidate_builds, 1u);
  s.p[17].x += 0.125;  // exactly skin/2
  call("at the limit");
  EXPECT_EQ(engine.stats().candidate_reuses, 1u) << "2·(skin/2) <= skin keeps the list";
  EXPECT_EQ(engine.stats().skin_displacement, 0.125);
  s.p[17].x += 0.0078125;  // past it (since the build)
  call("past the limit");
  EXPECT_EQ(engine.stats().candidate_builds, 2u) << "2·0.1328125 > skin rebuilds";
  EXPECT_EQ(engine.stats().skin_displacement, 0.1328125);
  call("after the rebuild");
  EXPECT_EQ(engine.stats().candidate_reuses, 2u);
  EXPECT_EQ(engine.stats().skin_displacement, 0.0);
  s.r[5] += 0.0625;  // growth counts too: 2·0.0625 <= skin
  call("grown");
  EXPECT_EQ(engine.stats().candidate_reuses, 3u);
  EXPECT_EQ(engine.stats().skin_growth, 0.0625);
  s.r[6] += 0.125;        // 2·0.125 <= skin, still kept
  s.p[6].y -= 0.0078125;  // but with the move: 2·(0.0078125 + 0.125) > skin
  call("grown and moved");
  EXPECT_EQ(engine.stats().candidate_builds, 3u);
}

// Pairs built exactly skin apart that close the gap exactly (each body skin/2 towards the other):
// they touch (a contact: touching counts) at a reused call; pairs one dyadic step further stay
// apart. Coordinates and radii are dyadic, so fp32 and fp64 hold them exactly.
TYPED_TEST(EngineSkinTest, PairsClosingExactlyTheSkinAreFound) {
  using Real = typename TypeParam::Real;
  SkinEngines<TypeParam> engines(0.25);
  auto& [engine, fresh, skin] = engines;
  const double ra = 0.5, rb = 0.75;
  Spheres s;
  std::mt19937_64 rng(9131);
  for (int k = 0; k < 200; ++k) {
    const double x = 8.0 * (k % 10), y = 8.0 * ((k / 10) % 10), z = 8.0 * (k / 100);
    const double gap = k % 2 ? 0.0078125 : 0.0;  // odd k: one step more than the skin apart
    const int axis = static_cast<int>(rng() % 3);
    Vec3<double> a{x, y, z}, b = a;
    (axis == 0 ? b.x : axis == 1 ? b.y : b.z) += ra + rb + skin + gap;
    s.add(a.x, a.y, a.z, ra);
    s.add(b.x, b.y, b.z, rb);
  }
  const Contacts<Real> built = engine.detect(BodiesView{s.p, s.r, {}, {}});
  EXPECT_EQ(built.size(), 0u);
  EXPECT_GE(engine.stats().candidates, 100u) << "the pairs skin apart are candidates";
  for (std::size_t i = 0; i + 1 < s.p.size(); i += 2) {  // each body skin/2 towards the other
    Vec3<double> d = s.p[i + 1] - s.p[i];
    const double len = std::sqrt(dot(d, d));
    d = (1 / len) * d;  // an axis: exact
    s.p[i] = s.p[i] + (skin / 2) * d;
    s.p[i + 1] = s.p[i + 1] - (skin / 2) * d;
  }
  const Contacts<Real> got = engine.detect(BodiesView{s.p, s.r, {}, {}});
  EXPECT_EQ(engine.stats().candidate_reuses, 1u);
  EXPECT_EQ(engine.stats().skin_displacement, skin / 2);
  const Contacts<Real> want = fresh.detect(BodiesView{s.p, s.r, {}, {}});
  EXPECT_EQ(want.size(), 100u) << "the even pairs touch exactly";
  EXPECT_EQ(compare_contacts(got, want), "identical");
  for (std::size_t k = 0; k < got.size(); ++k) EXPECT_EQ(got.distance[k], Real(0));
}

// A body count change, a report mask change and other ids rebuild (no skin check runs).
TYPED_TEST(EngineSkinTest, OtherBodiesRebuild) {
  SkinEngines<TypeParam> engines(0.2);
  auto& [engine, fresh, skin] = engines;
  EXPECT_EQ(skin, engine.options().skin);
  Spheres s = random_spheres(2500, 0.5, 1.0, 9141);
  std::vector<std::uint8_t> report(s.r.size(), kReportedBit);
  auto call = [&](const BodiesView& v, const std::string& at) {
    ASSERT_EQ(compare_contacts(engine.detect(v), fresh.detect(v)), "identical") << at;
  };
  call(BodiesView{s.p, s.r, {}, {}}, "build");
  call(BodiesView{s.p, s.r, {}, {}}, "same bodies");
  EXPECT_EQ(engine.stats().candidate_reuses, 1u);
  EXPECT_TRUE(has_stage(engine.times(), "skin"));
  const BodiesView fewer{{s.p.data(), s.p.size() - 1}, {s.r.data(), s.r.size() - 1}, {}, {}};
  call(fewer, "one body less");
  EXPECT_EQ(engine.stats().candidate_builds, 2u);
  EXPECT_FALSE(has_stage(engine.times(), "skin")) << "another count is not checked";
  call(BodiesView{s.p, s.r, {}, {}}, "all again");
  EXPECT_EQ(engine.stats().candidate_builds, 3u);
  call(BodiesView{s.p, s.r, {}, report}, "a report mask");
  EXPECT_EQ(engine.stats().candidate_builds, 4u) << "a mask where there was none";
  report[11] = 0;
  call(BodiesView{s.p, s.r, {}, report}, "one report byte changed");
  EXPECT_EQ(engine.stats().candidate_builds, 5u);
  EXPECT_TRUE(has_stage(engine.times(), "skin")) << "same count and ids: the check finds the mask";
  call(BodiesView{s.p, s.r, {}, report}, "same mask");
  EXPECT_EQ(engine.stats().candidate_reuses, 2u);
  std::vector<std::int64_t> id(s.r.size());
  for (std::size_t i = 0; i < id.size(); ++i) id[i] = std::int64_t(i) + 1;
  call(BodiesView{s.p, s.r, id, report}, "other ids");
  EXPECT_EQ(engine.stats().candidate_builds, 6u);
}

// Skin 0 (the default) is today's engine: no check, no counters, the stage list of before.
TYPED_TEST(EngineSkinTest, NoSkinKeepsNothing) {
  using Real = typename TypeParam::Real;
  Engine<Real> engine(options_for(TypeParam::backend, 0));
  const Spheres s = random_spheres(1500, 0.5, 1.0, 9151);
  for (int call = 0; call < 3; ++call) engine.detect(BodiesView{s.p, s.r, {}, {}});
  EXPECT_EQ(engine.stats().candidate_builds, 0u);
  EXPECT_EQ(engine.stats().candidate_reuses, 0u);
  EXPECT_FALSE(has_stage(engine.times(), "skin"));
  EXPECT_EQ(engine.stats().candidates, engine.stats().contacts) << "spheres_touch: no rejecting narrow";
  EXPECT_THROW(Engine<Real>(options_for(TypeParam::backend, -0.1)), UsageError);
  EXPECT_THROW(Engine<Real>(options_for(TypeParam::backend, std::nan(""))), UsageError);
}

// Mixed scenes: spheres and ellipsoids move, the ellipsoids turn and change their semi-axes (the
// bounding radius stays the largest semi-axis: its growth is measured), every call equals a fresh
// skin-0 detection, solver flags included; turning alone keeps the list (the candidates are
// bounding-sphere overlaps, which a rotation does not change).
TYPED_TEST(EngineSkinTest, MixedScenesEqualFreshDetection) {
  using Real = typename TypeParam::Real;
  SkinEngines<TypeParam> engines(0.1);
  auto& [engine, fresh, skin] = engines;
  ShapeScene s = make_scene("skin mixed", 9161, 800, 0.5, 13.0);
  std::mt19937_64 rng(9162);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int call = 0; call < 16; ++call) {
    const std::string at = s.name + " call " + std::to_string(call);
    const Contacts<Real> got = engine.detect(s.view());
    const EngineStats st = engine.stats();
    const Contacts<Real> want = fresh.detect(s.view());
    ASSERT_EQ(compare_contacts(got, want), "identical") << at;
    EXPECT_EQ(st.narrow_fallbacks, fresh.stats().narrow_fallbacks) << at;
    EXPECT_EQ(st.narrow_unconverged, fresh.stats().narrow_unconverged) << at;
    EXPECT_EQ(st.narrow_hard, fresh.stats().narrow_hard) << at;
    EXPECT_GT(got.size(), 50u) << at;
    for (std::size_t i = 0; i < s.p.size(); ++i) {
      s.p[i] = s.p[i] + Vec3<double>{0.006 * u(rng), 0.006 * u(rng), 0.006 * u(rng)};
      if (s.shape[i] != Shape::ellipsoid) continue;
      Quat<double>& q = s.q[i];  // a small turn, renormalised
      q = {q.w + 0.05 * u(rng), q.x + 0.05 * u(rng), q.y + 0.05 * u(rng), q.z + 0.05 * u(rng)};
      const double k = 1 / std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
      q = {q.w * k, q.x * k, q.y * k, q.z * k};
      s.axes[i] = (1 + 0.002 * u(rng)) * s.axes[i];  // the bounding radius follows (its growth counts)
      s.r[i] = std::max(s.axes[i].x, std::max(s.axes[i].y, s.axes[i].z));
    }
  }
  EXPECT_GE(engine.stats().candidate_reuses, 8u);
  EXPECT_GE(engine.stats().candidate_builds, 2u);
  // turning alone: the list is kept (a fresh engine: the check measures from its build)
  Engine<Real> turning(options_for(TypeParam::backend, skin));
  turning.detect(s.view());
  for (auto& q : s.q) q = {q.x, -q.w, q.z, -q.y};  // a quarter-turn product (still unit)
  const Contacts<Real> got = turning.detect(s.view());
  EXPECT_EQ(turning.stats().candidate_reuses, 1u);
  EXPECT_EQ(turning.stats().skin_displacement, 0.0);
  EXPECT_EQ(compare_contacts(got, fresh.detect(s.view())), "identical");
}

// The room a build reserves for the kept list its walk writes in place (core/kept_room.hpp): the
// last list's count and a half, one pair per entry before any list, never less than held.
TEST(KeptRoom, FromTheLastCountOrTheEntriesAndNeverShrinks) {
  EXPECT_EQ(kept_room(0, 7000, 0), 7000u);           // no list kept yet: one pair per entry
  EXPECT_EQ(kept_room(1000, 7000, 0), 1500u);        // the last count and a half, whatever the entries
  EXPECT_EQ(kept_room(1001, 10, 0), 1501u);          // (rounded down: 1001 / 2 = 500)
  EXPECT_EQ(kept_room(1000, 7000, 4000), 4000u);     // the room held already
  EXPECT_EQ(kept_room(0, 0, 0), 0u);                 // nothing to hold
  const std::uint64_t big = std::uint64_t(3) << 31;  // past 32 bits: no wrap
  EXPECT_EQ(kept_room(big, 0, 0), big + big / 2);
  // the count it starts from: the kept list's, else the last pair stage's (calls without a skin)
  EXPECT_EQ(kept_room_basis(1000, 5000), 1000u);
  EXPECT_EQ(kept_room_basis(0, 5000), 5000u);
  EXPECT_EQ(kept_room(kept_room_basis(0, 5000), 70000, 0), 7500u);  // not the entries
  EXPECT_EQ(kept_room(kept_room_basis(0, 0), 70000, 0), 70000u);    // no call yet: the entries
}

#if defined(CONTACTGRID_HAVE_CUDA)
// Device arrays (detect_device and detect_device_resident): the same walk on the GPU, each call equal
// to the CPU backend's fresh skin-0 detection of the same values (bit-identical backends).
TEST(EngineSkinCuda, DeviceArraysEqualFreshDetection) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  const double skin = 0.2;
  Engine<double> engine(options_for(Backend::cuda, skin));
  Engine<double> fresh(options_for(Backend::cpu, 0));
  Spheres s = random_spheres(20000, 0.5, 1.0, 9171);
  const std::size_t n = s.r.size();
  double *d_pos = nullptr, *d_rad = nullptr;
  ASSERT_EQ(cudaMalloc(&d_pos, 3 * n * sizeof(double)), cudaSuccess);
  ASSERT_EQ(cudaMalloc(&d_rad, n * sizeof(double)), cudaSuccess);
  std::mt19937_64 rng(9172);
  for (int call = 0; call < 20; ++call) {
    const std::string at = "call " + std::to_string(call);
    ASSERT_EQ(cudaMemcpy(d_pos, s.p.data(), 3 * n * sizeof(double), cudaMemcpyHostToDevice), cudaSuccess);
    ASSERT_EQ(cudaMemcpy(d_rad, s.r.data(), n * sizeof(double), cudaMemcpyHostToDevice), cudaSuccess);
    const DeviceBodiesView v{.position = d_pos, .radius = d_rad, .count = n};
    const Contacts<double> want = fresh.detect(BodiesView{s.p, s.r, {}, {}});
    if (call % 2) {
      ASSERT_EQ(compare_contacts(engine.detect_device(v), want), "identical") << at;
    } else {
      const DeviceContactsView<double> dc = engine.detect_device_resident(v);
      ASSERT_EQ(dc.count, want.size()) << at;
      std::vector<std::int64_t> a(dc.count), b(dc.count);
      std::vector<double> d(dc.count);
      ASSERT_EQ(cudaMemcpy(a.data(), dc.id_a, dc.count * sizeof(std::int64_t), cudaMemcpyDeviceToHost),
                cudaSuccess);
      ASSERT_EQ(cudaMemcpy(b.data(), dc.id_b, dc.count * sizeof(std::int64_t), cudaMemcpyDeviceToHost),
                cudaSuccess);
      ASSERT_EQ(cudaMemcpy(d.data(), dc.distance, dc.count * sizeof(double), cudaMemcpyDeviceToHost),
                cudaSuccess);
      EXPECT_TRUE(std::equal(a.begin(), a.end(), want.id_a.begin(), want.id_a.end())) << at;
      EXPECT_TRUE(std::equal(b.begin(), b.end(), want.id_b.begin(), want.id_b.end())) << at;
      EXPECT_TRUE(std::equal(d.begin(), d.end(), want.distance.begin(), want.distance.end())) << at;
    }
    random_step(s, 0.015, 0.001, rng);
  }
  EXPECT_GE(engine.stats().candidate_builds, 2u);
  EXPECT_GE(engine.stats().candidate_reuses, 10u);
  cudaFree(d_pos);
  cudaFree(d_rad);
}

// The resident steps' cell order (fp32 spheres, detect_resident: kernels/cuda/cell_order.cuh): the
// kept candidates and spheres in the bodies' cell order, the rows sorted by (a, b) when they come
// down. The bodies renumbered (CONTACTGRID_CUDA_RENUMBER=1: a cell order that is not the input
// order), with a report mask; every step equals the CPU's fresh detection, bit for bit, and so does
// the (a, b) path of CONTACTGRID_STEP_ORDER=file on a second engine. Every fourth step the cell
// engine detects once more under the knob: a kept list of the other order is never reused (that
// call builds, and so does the next one in cell order).
TEST(EngineSkinCuda, CellOrderResidentStepsEqualFreshDetection) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  const Env renumber("CONTACTGRID_CUDA_RENUMBER", "1");
  const double skin = 0.15;
  Engine<float> cell(options_for(Backend::cuda, skin)), file(options_for(Backend::cuda, skin));
  Engine<float> fresh(options_for(Backend::cpu, 0));
  Spheres s = random_spheres(30000, 0.5, 1.0, 9181);
  const std::size_t n = s.r.size();
  std::mt19937_64 rng(9182);
  std::vector<std::uint8_t> report(n);
  for (auto& m : report) m = static_cast<std::uint8_t>(rng() % 4 == 0 ? 0 : 1);
  cell.set_resident(BodiesView{s.p, s.r, {}, report});
  file.set_resident(BodiesView{s.p, s.r, {}, report});
  bool switched = false;
  for (int step = 0; step < 30; ++step) {
    const std::string at = "step " + std::to_string(step);
    if (step > 0) {
      random_step(s, 0.01, 0.0, rng);
      cell.write_resident(0, n, s.p.data(), s.r.data());
      file.write_resident(0, n, s.p.data(), s.r.data());
    }
    const Contacts<float> want = fresh.detect(BodiesView{s.p, s.r, {}, report});
    ASSERT_GT(want.size(), 1000u) << at;
    const std::uint64_t builds = cell.stats().candidate_builds;
    ASSERT_EQ(cell.detect_resident(), want.size()) << at;
    ASSERT_EQ(compare_contacts(cell.resident_contacts(), want), "identical") << at << " (cell order)";
    if (switched) {
      EXPECT_EQ(cell.stats().candidate_builds, builds + 1) << at << ": after the file order";
    }
    switched = false;
    {
      const Env order("CONTACTGRID_STEP_ORDER", "file");
      ASSERT_EQ(file.detect_resident(), want.size()) << at;
      ASSERT_EQ(compare_contacts(file.resident_contacts(), want), "identical") << at << " (file order)";
      if (step % 4 == 3) {
        const std::uint64_t before = cell.stats().candidate_builds;
        ASSERT_EQ(cell.detect_resident(), want.size()) << at << " (cell engine, file order)";
        ASSERT_EQ(compare_contacts(cell.resident_contacts(), want), "identical") << at << " (switched)";
        EXPECT_EQ(cell.stats().candidate_builds, before + 1) << at << ": a cell-order list is not reused";
        switched = true;
      }
    }
  }
  EXPECT_GE(file.stats().candidate_builds, 2u);
  EXPECT_GE(file.stats().candidate_reuses, 15u);
}

// An engine whose skin is chosen per call (skin_auto) keeps the grid broad phase on a scene of one
// size class large enough for auto's device levels (2^21 bodies: broad_phase.cpp), so its builds keep
// their lists in cell order; a skin-0 engine takes the levels. Every step the same rows as the fresh
// engine's, bit for bit, with builds and reuses both seen.
TEST(EngineSkinCuda, AutoSkinKeepsTheGridOnLargeScenes) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  EngineOptions automatic = options_for(Backend::cuda, 0);
  automatic.skin_auto = true;
  Engine<float> tuned(automatic), fresh(options_for(Backend::cuda, 0));
  Spheres s = random_spheres(std::size_t(1) << 21, 0.5, 1.0, 9191);
  const std::size_t n = s.r.size();
  std::mt19937_64 rng(9192);
  tuned.set_resident(BodiesView{s.p, s.r, {}, {}});
  for (int step = 0; step < 12; ++step) {
    const std::string at = "step " + std::to_string(step);
    if (step > 0) {
      random_step(s, 0.005, 0.0, rng);
      tuned.write_resident(0, n, s.p.data(), s.r.data());
    }
    const Contacts<float> want = fresh.detect(BodiesView{s.p, s.r, {}, {}});
    EXPECT_EQ(fresh.stats().broad_phase, BroadPhase::levels) << at;
    ASSERT_EQ(tuned.detect_resident(), want.size()) << at;
    ASSERT_EQ(compare_contacts(tuned.resident_contacts(), want), "identical") << at;
    EXPECT_EQ(tuned.stats().broad_phase, BroadPhase::grid) << at;
  }
  EXPECT_GE(tuned.stats().candidate_builds, 1u);
  EXPECT_GE(tuned.stats().candidate_reuses, 5u);
}

// A cell-order build's pair stage writes the kept list itself (cell-order indices, in room sized by
// the previous build's count: core/kept_room.hpp; kernels/cuda/pairs.cuh), and walks again into room
// of the counted size where the walk finds more than that room (CONTACTGRID_STEP_REBUILD=fill: the
// counted fill and the inverse permutation): a build whose skin grows fiftyfold (the second walk),
// then one whose skin shrinks (in place again), with and without renumbered bodies, with a report
// mask. Every step equals the CPU's fresh detection bit for bit, and the engines under
// CONTACTGRID_STEP_BUILD=copy (the mapping after the walk), CONTACTGRID_STEP_REBUILD=fill and
// CONTACTGRID_STEP_BUILD_WINDOW=32 (31 entries after each in shared memory, not 63; the fiftyfold skin's
// cells run far past both) keep the same candidates, count the same tests and build at the same steps;
// under CONTACTGRID_STEP_PACK=separate (the check, then a gather into cell order, not the fused pass)
// the same rows, builds and measured motion. The fill engine's narrow tests 2 candidates a thread
// (CONTACTGRID_STEP_NARROW_ITEMS=2) instead of 4.
TEST(EngineSkinCuda, CellOrderBuildsWriteTheKeptListInPlace) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  for (const char* renumber : {"1", "0"}) {
    const Env numbering("CONTACTGRID_CUDA_RENUMBER", renumber);
    Engine<float> in_place(options_for(Backend::cuda, 0.1)), copy(options_for(Backend::cuda, 0.1));
    Engine<float> fill(options_for(Backend::cuda, 0.1)), narrow(options_for(Backend::cuda, 0.1));
    Engine<float> separate(options_for(Backend::cuda, 0.1));
    Engine<float> fresh(options_for(Backend::cpu, 0));
    Spheres s = random_spheres(20000, 0.5, 1.0, 9191);
    const std::size_t n = s.r.size();
    std::mt19937_64 rng(9192);
    std::vector<std::uint8_t> report(n);
    for (auto& m : report) m = static_cast<std::uint8_t>(rng() % 5 == 0 ? 0 : 1);
    for (Engine<float>* e : {&in_place, &copy, &fill, &narrow, &separate})
      e->set_resident(BodiesView{s.p, s.r, {}, report});
    std::uint64_t candidates_before = 0, entries_first = 0;
    for (int step = 0; step < 12; ++step) {
      const std::string at = std::string("renumber ") + renumber + ", step " + std::to_string(step);
      if (step == 4 || step == 8) {  // a new skin, built now: 5 (more candidates than the room), 0.2
        for (Engine<float>* e : {&in_place, &copy, &fill, &narrow, &separate}) {
          e->set_skin(step == 4 ? 5.0 : 0.2);
          e->rebuild_candidates();
        }
      }
      if (step > 0) {
        random_step(s, 0.005, 0.0, rng);
        for (Engine<float>* e : {&in_place, &copy, &fill, &narrow, &separate})
          e->write_resident(0, n, s.p.data(), s.r.data());
      }
      const Contacts<float> want = fresh.detect(BodiesView{s.p, s.r, {}, report});
      ASSERT_GT(want.size(), 500u) << at;
      const std::uint64_t builds = in_place.stats().candidate_builds;
      ASSERT_EQ(in_place.detect_resident(), want.size()) << at;
      ASSERT_EQ(compare_contacts(in_place.resident_contacts(), want), "identical") << at << " (in place)";
      {
        const Env build("CONTACTGRID_STEP_BUILD", "copy");
        ASSERT_EQ(copy.detect_resident(), want.size()) << at;
        ASSERT_EQ(compare_contacts(copy.resident_contacts(), want), "identical") << at << " (copy)";
      }
      {
        const Env rebuild("CONTACTGRID_STEP_REBUILD", "fill"), items("CONTACTGRID_STEP_NARROW_ITEMS", "2");
        ASSERT_EQ(fill.detect_resident(), want.size()) << at;
        ASSERT_EQ(compare_contacts(fill.resident_contacts(), want), "identical") << at << " (fill)";
      }
      {
        const Env window("CONTACTGRID_STEP_BUILD_WINDOW", "32");
        ASSERT_EQ(narrow.detect_resident(), want.size()) << at;
        ASSERT_EQ(compare_contacts(narrow.resident_contacts(), want), "identical") << at << " (window 32)";
      }
      {
        const Env pack("CONTACTGRID_STEP_PACK", "separate");
        ASSERT_EQ(separate.detect_resident(), want.size()) << at;
        ASSERT_EQ(compare_contacts(separate.resident_contacts(), want), "identical")
            << at << " (pack separate)";
        EXPECT_EQ(separate.stats().candidate_builds, in_place.stats().candidate_builds) << at;
        EXPECT_EQ(separate.stats().skin_displacement, in_place.stats().skin_displacement) << at;
      }
      const bool built = in_place.stats().candidate_builds > builds;
      EXPECT_EQ(built, step == 0 || step == 4 || step == 8) << at;
      EXPECT_EQ(in_place.stats().candidates, copy.stats().candidates) << at << ": the same kept list";
      EXPECT_EQ(in_place.stats().candidate_builds, copy.stats().candidate_builds) << at;
      EXPECT_EQ(in_place.stats().candidates, fill.stats().candidates) << at << ": the same kept list";
      EXPECT_EQ(in_place.stats().pair_tests, fill.stats().pair_tests) << at << ": counted once";
      EXPECT_EQ(in_place.stats().candidate_builds, fill.stats().candidate_builds) << at;
      EXPECT_EQ(in_place.stats().candidates, narrow.stats().candidates) << at << ": window 32";
      EXPECT_EQ(in_place.stats().pair_tests, narrow.stats().pair_tests) << at << ": window 32";
      // the room of the build at step 4: the first build's (one pair per entry), or the last list's
      // count and a half; the fiftyfold skin's list outgrows it
      if (step == 8) {
        EXPECT_EQ(in_place.stats().pair_walks, 1) << at << ": the last count and a half hold it";
      }
      if (step == 0) entries_first = in_place.stats().entries;
      if (step == 4) {
        EXPECT_GT(in_place.stats().candidates,
                  std::max(candidates_before + candidates_before / 2, entries_first))
            << at;
        EXPECT_EQ(in_place.stats().pair_walks, 2) << at << ": walked again into the counted room";
      }
      candidates_before = in_place.stats().candidates;
    }
  }
}

// The first build after calls without a skin takes its room from their pair count
// (core/kept_room.hpp: kept_room_basis) rather than one pair per entry: a cell-order engine detects
// from scratch (skin 0), then builds and reuses with a skin; a skin far above the first's makes the
// second build walk again. Every step equals the CPU's fresh detection bit for bit, and the engine
// under CONTACTGRID_STEP_REBUILD=fill keeps the same candidates and counts the same tests.
TEST(EngineSkinCuda, TheFirstBuildAfterFreshCallsTakesItsRoomFromTheirCount) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  Engine<float> now(options_for(Backend::cuda, 0)), former(options_for(Backend::cuda, 0));
  Engine<float> fresh(options_for(Backend::cpu, 0));
  Spheres s = random_spheres(25000, 0.5, 1.0, 9201);
  const std::size_t n = s.r.size();
  std::mt19937_64 rng(9202);
  for (Engine<float>* e : {&now, &former}) e->set_resident(BodiesView{s.p, s.r, {}, {}});
  for (int step = 0; step < 14; ++step) {
    const std::string at = "step " + std::to_string(step);
    if (step == 3 || step == 8) {  // a skin from now on (step 3), then one far larger (step 8)
      for (Engine<float>* e : {&now, &former}) {
        e->set_skin(step == 3 ? 0.1 : 2.0);
        e->rebuild_candidates();
      }
    }
    if (step > 0) {
      random_step(s, 0.004, 0.0, rng);
      for (Engine<float>* e : {&now, &former}) e->write_resident(0, n, s.p.data(), s.r.data());
    }
    const Contacts<float> want = fresh.detect(BodiesView{s.p, s.r, {}, {}});
    ASSERT_GT(want.size(), 500u) << at;
    ASSERT_EQ(now.detect_resident(), want.size()) << at;
    ASSERT_EQ(compare_contacts(now.resident_contacts(), want), "identical") << at;
    {
      const Env rebuild("CONTACTGRID_STEP_REBUILD", "fill");
      ASSERT_EQ(former.detect_resident(), want.size()) << at;
      ASSERT_EQ(compare_contacts(former.resident_contacts(), want), "identical") << at << " (fill)";
    }
    EXPECT_EQ(now.stats().candidates, former.stats().candidates) << at;
    EXPECT_EQ(now.stats().pair_tests, former.stats().pair_tests) << at;
    EXPECT_EQ(now.stats().candidate_builds, former.stats().candidate_builds) << at;
    // the build at step 3 has the fresh calls' count and a half (a skin of 0.1 adds less than a half);
    // the one at step 8 (a skin twenty times that) outgrows it and walks again
    if (step == 3) {
      EXPECT_EQ(now.stats().pair_walks, 1) << at;
    }
    if (step == 8) {
      EXPECT_EQ(now.stats().pair_walks, 2) << at;
    }
  }
  EXPECT_EQ(now.stats().candidate_builds, 2u);  // steps 3 and 8
  EXPECT_GE(now.stats().candidate_reuses, 8u);
}
#endif

}  // namespace
}  // namespace cg::test
