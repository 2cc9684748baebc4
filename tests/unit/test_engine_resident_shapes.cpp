// Resident bodies with shapes (issue #12, the resident steps for ellipsoid and mixed scenes): one test
// body over both backends and precisions (CUDA cases skip visibly without a GPU). The oracle of every
// detect_resident is Engine::detect on the same rows (itself checked against the exact long-double
// reference in test_engine_shapes.cpp): the same contacts bit for bit, after position, orientation and
// semi-axis refreshes of row ranges, with and without a skin (a skin's contacts are a skin-0
// detection's, EngineOptions::skin) and with a report mask.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "backends.hpp"
#include "core/quat.hpp"
#include "engine.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"

namespace cg::test {
namespace {

template <class Cfg>
class ResidentShapesTest : public ::testing::Test {};
TYPED_TEST_SUITE(ResidentShapesTest, AllConfigs, ConfigNames);

template <class Real>
void expect_identical(const Contacts<Real>& want, const Contacts<Real>& got, const std::string& what) {
  EXPECT_EQ(compare_contacts(got, want), "identical") << what;
  EXPECT_EQ(got.size(), want.size()) << what;
}

// A unit quaternion turned by a small random rotation (angle <= max_angle rad), renormalised.
Quat<double> turned(const Quat<double>& q, double max_angle, std::mt19937_64& rng) {
  std::normal_distribution<double> g;
  std::uniform_real_distribution<double> u(0, 1);
  double ax = g(rng), ay = g(rng), az = g(rng);
  const double an = std::sqrt(ax * ax + ay * ay + az * az), h = 0.5 * max_angle * u(rng);
  const double s = std::sin(h) / an, c = std::cos(h);
  const Quat<double> d{c, ax * s, ay * s, az * s};  // d * q
  Quat<double> r{d.w * q.w - d.x * q.x - d.y * q.y - d.z * q.z, d.w * q.x + d.x * q.w + d.y * q.z - d.z * q.y,
                 d.w * q.y - d.x * q.z + d.y * q.w + d.z * q.x,
                 d.w * q.z + d.x * q.y - d.y * q.x + d.z * q.w};
  const double k = 1 / std::sqrt(r.w * r.w + r.x * r.x + r.y * r.y + r.z * r.z);
  return {r.w * k, r.x * k, r.y * k, r.z * k};
}

// Steps of a granular simulation on the resident rows: each moves one range of rows, turns the
// ellipsoids of another, shrinks a few ellipsoids (semi-axes with their bounding radius); the host copy
// `s` mirrors every write and detect() on it is the oracle. Returns the steps that reused candidates.
template <class Real>
std::uint64_t run_steps(Backend backend, ShapeScene s, const std::vector<std::uint8_t>& report, double skin,
                        Fields fields, std::uint64_t seed) {
  const std::string what = s.name + " skin " + std::to_string(skin) + " " + to_string(fields) +
                           (report.empty() ? "" : " with report mask");
  Engine<Real> resident({.backend = backend, .fields = fields, .skin = skin});
  Engine<Real> oracle({.backend = backend, .fields = fields});
  auto view = [&] {
    BodiesView v = s.view();
    v.report = report;
    return v;
  };
  resident.set_resident(view());
  EXPECT_EQ(resident.resident_size(), s.p.size());
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  const std::size_t n = s.p.size();
  const double step = skin > 0 ? skin / 8 : 0.02;  // centres move less than skin/2 over a few steps
  std::size_t compared_contacts = 0;
  for (int k = 0; k < 6; ++k) {
    const std::string at = what + " step " + std::to_string(k);
    resident.detect_resident();
    const Contacts<Real> want = oracle.detect(view());
    expect_identical(want, resident.resident_contacts(), at);
    EXPECT_EQ(resident.stats().ellipsoids, oracle.stats().ellipsoids) << at;
    compared_contacts += want.size();
    // rows [first, first + count) move (positions written with their radii)
    const std::size_t first = (k * 97) % (n / 2), count = n / 3;
    for (std::size_t i = first; i < first + count; ++i)
      s.p[i] = {s.p[i].x + step * u(rng), s.p[i].y + step * u(rng), s.p[i].z + step * u(rng)};
    resident.write_resident(first, count, s.p.data() + first, s.r.data() + first);
    // rows [o_first, o_first + o_count) turn: orientations only (semi-axes kept: null)
    const std::size_t o_first = (k * 131 + 40) % (n / 2), o_count = n / 2;
    for (std::size_t i = o_first; i < o_first + o_count; ++i)
      if (s.shape[i] == Shape::ellipsoid) s.q[i] = turned(s.q[i], 0.6, rng);
    resident.write_resident_shapes(o_first, o_count, nullptr, s.q.data() + o_first);
    // every other step a few ellipsoids shrink by 5 %: semi-axes, then the bounding radius
    if (k % 2 == 1) {
      const std::size_t e_first = (k * 53) % (n - 20);
      for (std::size_t i = e_first; i < e_first + 20; ++i)
        if (s.shape[i] == Shape::ellipsoid) {
          s.axes[i] = {0.95 * s.axes[i].x, 0.95 * s.axes[i].y, 0.95 * s.axes[i].z};
          s.r[i] = std::max(s.axes[i].x, std::max(s.axes[i].y, s.axes[i].z));
        }
      resident.write_resident_shapes(e_first, 20, s.axes.data() + e_first, nullptr);
      resident.write_resident(e_first, 20, s.p.data() + e_first, s.r.data() + e_first);
    }
  }
  EXPECT_GT(compared_contacts, 100u) << what << ": the scene should have contacts";
  // what was written is what is read back
  std::vector<Vec3<double>> axes(n);
  std::vector<Quat<double>> q(n);
  resident.read_resident_shapes(0, n, axes.data(), q.data());
  EXPECT_EQ(std::memcmp(axes.data(), s.axes.data(), n * sizeof(axes[0])), 0) << what;
  EXPECT_EQ(std::memcmp(q.data(), s.q.data(), n * sizeof(q[0])), 0) << what;
  std::vector<Quat<double>> some(10, Quat<double>{9, 9, 9, 9});
  resident.read_resident_shapes(n - 10, 10, nullptr, some.data());  // one field alone
  EXPECT_EQ(std::memcmp(some.data(), s.q.data() + n - 10, 10 * sizeof(some[0])), 0) << what;
  if (skin > 0) {
    EXPECT_GT(resident.stats().candidate_builds, 0u) << what;
  }
  return resident.stats().candidate_reuses;
}

TYPED_TEST(ResidentShapesTest, EqualsDetectAfterRefreshes) {
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  using Real = typename TypeParam::Real;
  const ShapeScene mixed = make_scene("mixed", 71, 900, 0.4, 13.0);
  const ShapeScene ellipsoids = make_scene("ellipsoids", 72, 700, 1.0, 12.0);
  std::vector<std::uint8_t> report(mixed.p.size());
  for (std::size_t i = 0; i < report.size(); ++i)  // owned and ghost rows, some boundary ones paired
    report[i] = i % 3 == 0 ? 0 : (i % 7 == 0 ? kReportedBit | kPairedBit : kReportedBit);
  std::uint64_t reuses = 0;
  for (double skin : {0.0, 0.1}) {
    reuses += run_steps<Real>(TypeParam::backend, mixed, {}, skin, Fields::full, 1);
    reuses += run_steps<Real>(TypeParam::backend, ellipsoids, {}, skin, Fields::basic, 2);
    reuses += run_steps<Real>(TypeParam::backend, mixed, report, skin, Fields::basic, 3);
  }
  EXPECT_GT(reuses, 0u) << "the skin runs should reuse candidates across steps";
}

// A sphere-only resident set stays the sphere path: the same bits as detect(), and no shape rows to
// refresh. Length mismatches are refused.
TYPED_TEST(ResidentShapesTest, SphereRowsAndMisuse) {
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  using Real = typename TypeParam::Real;
  const Backend b = TypeParam::backend;
  ShapeScene s = make_scene("spheres", 73, 500, 0.0, 10.0);
  Engine<Real> e({.backend = b, .fields = Fields::full});
  Engine<Real> oracle({.backend = b, .fields = Fields::full});
  e.set_resident(BodiesView{s.p, s.r, {}, {}});
  e.detect_resident();
  expect_identical(oracle.detect(BodiesView{s.p, s.r, {}, {}}), e.resident_contacts(),
                   "spheres, no shape rows");
  Quat<double> q{1, 0, 0, 0};
  EXPECT_THROW(e.write_resident_shapes(0, 1, nullptr, &q), UsageError);
  EXPECT_THROW(e.read_resident_shapes(0, 1, nullptr, &q), UsageError);
  // shape rows of spheres only: the sphere path's bits
  e.set_resident(s.view());
  e.detect_resident();
  expect_identical(oracle.detect(s.view()), e.resident_contacts(), "spheres with shape rows");
  EXPECT_EQ(e.stats().ellipsoids, 0u);
  EXPECT_THROW(e.write_resident_shapes(499, 2, nullptr, &q), UsageError);
  ShapeScene bad = s;
  bad.axes.pop_back();
  EXPECT_THROW(e.set_resident(bad.view()), UsageError);
  BodiesView half = BodiesView{s.p, s.r, {}, {}};
  half.orientation = s.q;  // orientations without kinds
  EXPECT_THROW(e.set_resident(half), UsageError);
  // a bad orientation written into the rows: detect_resident names the body (InputError)
  ShapeScene e_scene = make_scene("ellipsoids", 74, 50, 1.0, 6.0);
  e.set_resident(e_scene.view());
  const Quat<double> zero{0, 0, 0, 0};
  e.write_resident_shapes(17, 1, nullptr, &zero);
  try {
    e.detect_resident();
    ADD_FAILURE() << "a zero quaternion should be refused";
  } catch (const InputError& err) {
    EXPECT_NE(std::string(err.what()).find("17"), std::string::npos) << err.what();
  }
}

// A bad row written between two steps that reuse the kept candidates (a skin: turning keeps the
// bounding spheres, so the list is reused) is refused as on a step that rebuilds: InputError naming the
// body, no contacts (the device checks the rows where it packs them: cuda/shapes.cuh).
TYPED_TEST(ResidentShapesTest, BadRowOnAReuseStepIsRefused) {
  CG_SKIP_WITHOUT_BACKEND(TypeParam);
  using Real = typename TypeParam::Real;
  ShapeScene s = make_scene("ellipsoids", 75, 400, 1.0, 9.0);
  Engine<Real> e({.backend = TypeParam::backend, .fields = Fields::basic, .skin = 0.2});
  e.set_resident(s.view());
  e.detect_resident();  // builds the list
  std::mt19937_64 rng(5);
  const Quat<double> turned_q = turned(s.q[5], 0.3, rng);
  e.write_resident_shapes(5, 1, nullptr, &turned_q);
  e.detect_resident();  // reuses it
  EXPECT_EQ(e.stats().candidate_reuses, 1u);
  const Vec3<double> negative{0.5, -0.25, 0.5};
  e.write_resident_shapes(23, 1, &negative, nullptr);
  try {
    e.detect_resident();
    ADD_FAILURE() << "a negative semi-axis should be refused";
  } catch (const InputError& err) {
    EXPECT_NE(std::string(err.what()).find("23"), std::string::npos) << err.what();
  }
}

}  // namespace
}  // namespace cg::test
