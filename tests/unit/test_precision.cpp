// The precision modes (issue #13, docs/PRECISION.md) against the exact long-double
// reference (src/reference, cg_reference), one body over both backends (CUDA cases skip without a GPU):
//   fp64   decisions on the frame-local doubles, rows from the world doubles: normals and points
//          exact to a few ulps even for centres 1e-12 apart at 1e6;
//   mixed  fp32 broad phase + fp64 narrow phase: bit-identical to fp64 on every scene;
//   fp32   normals it cannot resolve come from fp64 (counted), never a silent wrong normal; scenes
//          whose float32 world positions would be off by more than r_max/4 are refused.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "backends.hpp"
#include "core/narrow.hpp"
#include "engine.hpp"
#include "grid_plan.hpp"
#include "reference/sphere_reference.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"

namespace cg::test {
namespace {

using exact::RefContact;
using exact::reference_contacts;

template <class T>
class PrecisionTest : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(T); }
  // One detection in mode `mode` (Real: float for fp32, double for fp64 and mixed), every field.
  template <class Real>
  Contacts<Real> run(const Spheres& s, Precision mode, Backend backend = T::backend, int threads = 0) {
    EngineOptions o;
    o.backend = backend;
    o.fields = Fields::full;
    o.threads = threads;
    o.fp32_broad_phase = mode == Precision::mixed;
    Engine<Real> e(o);
    EXPECT_EQ(e.precision(), mode);
    Contacts<Real> c = e.detect(BodiesView{s.p, s.r, {}, {}});
    m_stats = e.stats();
    return c;
  }
  EngineStats m_stats;
};
TYPED_TEST_SUITE(PrecisionTest, BackendTypes, BackendTypeNames);

constexpr double kDeg = 3.14159265358979323846 / 180;

// Pairs of radius-0.5 spheres whose centres are delta = 1e-3 … 1e-12 apart (random directions)
// around `base`, 10 apart from each other, plus `touching` well-separated pairs (centres 0.9 apart).
Spheres nearly_coincident(double base, int touching, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g;
  Spheres s;
  s.name = "nearly coincident at " + std::to_string(base);
  double x = base;
  for (int e = 3; e <= 12; ++e)
    for (int k = 0; k < 4; ++k, x += 10) {
      double u[3] = {g(rng), g(rng), g(rng)};
      const double len = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]), delta = std::pow(10.0, -e);
      const Vec3<double> a{x, 0.7 * base, 0.3 * base};
      s.add(a.x, a.y, a.z, 0.5);
      s.add(a.x + delta * u[0] / len, a.y + delta * u[1] / len, a.z + delta * u[2] / len, 0.5);
    }
  for (int k = 0; k < touching; ++k, x += 10) {
    s.add(x, 0.7 * base, 0.3 * base, 0.5);
    s.add(x + 0.9, 0.7 * base, 0.3 * base, 0.5);
  }
  return s;
}

// The largest angle (degrees) between the normals and the reference's, and the largest position
// error relative to |centre| + r; every reference pair must be a contact (they all overlap deeply).
template <class Real>
void worst_errors(const Spheres& s, const Contacts<Real>& c, double& angle_deg, double& pos_rel) {
  const auto ref = reference_contacts(s.p, s.r);
  ASSERT_EQ(c.size(), ref.size()) << s.name;
  angle_deg = pos_rel = 0;
  for (std::size_t k = 0; k < ref.size(); ++k) {
    const RefContact& r = ref[k];
    ASSERT_EQ(c.id_a[k], r.a);
    ASSERT_EQ(c.id_b[k], r.b);
    const Vec3<Real> n = c.normal_on_b[k];
    const long double dn[3] = {n.x - r.n[0], n.y - r.n[1], n.z - r.n[2]};
    const double chord = double(std::sqrt(dn[0] * dn[0] + dn[1] * dn[1] + dn[2] * dn[2]));
    angle_deg = std::max(angle_deg, 2 * std::asin(std::min(1.0, chord / 2)) / kDeg);
    const Vec3<double> a = s.p[std::size_t(r.a)];
    const double scale = std::max({std::fabs(a.x), std::fabs(a.y), std::fabs(a.z)}) + s.r[std::size_t(r.a)];
    const Vec3<Real> pa = c.position_on_a[k], pb = c.position_on_b[k];
    const long double e[6] = {pa.x - r.pa[0], pa.y - r.pa[1], pa.z - r.pa[2],
                              pb.x - r.pb[0], pb.y - r.pb[1], pb.z - r.pb[2]};
    for (long double v : e) pos_rel = std::max(pos_rel, double(std::fabs(v)) / scale);
  }
}

// worst_errors() within the bounds of a mode.
template <class Real>
void expect_within(const Spheres& s, const Contacts<Real>& c, double max_deg, double max_rel) {
  double angle = 0, pos = 0;
  worst_errors(s, c, angle, pos);
  EXPECT_LT(angle, max_deg) << s.name;
  EXPECT_LT(pos, max_rel) << s.name;
}

// fp64 (and mixed, bit for bit): exact centre differences from the world doubles, so normals within
// 1e-9° and points within 1e-12 of |centre| + r even 1e-12 apart (issue #13: 0.0135° and 2e-4 before,
// near 70, because the frame shift rounded each centre first).
TYPED_TEST(PrecisionTest, NearlyCoincidentCentresAreExactInFp64AndMixed) {
  for (double base : {70.0, 1e6}) {
    const Spheres s = nearly_coincident(base, 8, 1301);
    const Contacts<double> fp64 = this->template run<double>(s, Precision::fp64);
    expect_within(s, fp64, 1e-9, 1e-12);
    for (std::size_t k = 0; k < fp64.size(); ++k) {  // local points are the offsets themselves
      const double ra = s.r[std::size_t(fp64.id_a[k])];
      EXPECT_EQ(fp64.local_point_a[k].x, -ra * fp64.normal_on_b[k].x);
    }
    EXPECT_EQ(this->m_stats.fp64_rows, 0u);
    const Contacts<double> mixed = this->template run<double>(s, Precision::mixed);
    EXPECT_EQ(compare_contacts(mixed, fp64), "identical") << s.name;
  }
}

// fp32: the normals it cannot resolve are recomputed in fp64 and counted; the others stay within the
// documented bound sqrt(3)·2^-12 rad (0.024°); points within ulp32 of the world coordinate.
TYPED_TEST(PrecisionTest, Fp32NeverGivesASilentWrongNormal) {
  for (double base : {70.0, 1e6}) {
    const Spheres s = nearly_coincident(base, 8, 1302);
    const Contacts<float> c = this->template run<float>(s, Precision::fp32);
    expect_within(s, c, 0.025, 4 * std::numeric_limits<float>::epsilon());
    // every pair closer than 1e-4 is below fp32's resolution (2^-11 of its largest local coordinate,
    // >= 0.5 here); the 8 well-separated pairs are not
    EXPECT_GE(this->m_stats.fp64_rows, 4u * 9u) << s.name;
    EXPECT_LE(this->m_stats.fp64_rows, c.size() - 8) << s.name;
  }
}

// mixed = fp64, every field bit for bit, on random and adversarial scenes (the fp32 broad phase
// loses no pair that fp64 decides is a contact; the narrow stage decides as fp64's pair stage).
TYPED_TEST(PrecisionTest, MixedEqualsFp64OnEveryScene) {
  const Spheres scenes[] = {random_spheres(20000, 0.5, 1.0, 1311),
                            random_spheres(20000, 0.01, 1.0, 1312),
                            random_spheres(8000, 0.5, 1.0, 1313).translated({1e6, -1e6, 1e6}),
                            random_spheres(8000, 0.5, 1.0, 1314).translated({1e8, 1e8, -1e8}),
                            clustered(4000, 1315),
                            one_cell(300, 1316),
                            on_boundaries(1317),
                            coincident(1318),
                            tangent(1319),
                            tangent(1320).translated({1e6, 0, 0})};
  for (const Spheres& s : scenes) {
    const Contacts<double> fp64 = this->template run<double>(s, Precision::fp64);
    const Contacts<double> mixed = this->template run<double>(s, Precision::mixed);
    EXPECT_GE(this->m_stats.candidates, mixed.size()) << s.name;
    EXPECT_GT(mixed.size(), 0u) << s.name;
    EXPECT_EQ(compare_contacts(mixed, fp64), "identical") << s.name;
  }
}

// Exactly tangent pairs, and ±1 ulp in double (inside every band: either decision) and ±1 ulp of
// float at the pair's coordinate (outside fp64's band, and outside fp32's at 1e6): those decisions
// equal the exact ones.
TYPED_TEST(PrecisionTest, TangentPlusMinusOneUlpDecidedExactlyOutsideTheBand) {
  for (double base : {70.0, 1e6}) {
    Spheres s;
    s.name = "tangent ±1 ulp at " + std::to_string(base);
    enum Kind { exact, up64, down64, up32, down32 };
    std::vector<Kind> kind;
    double x = base;
    for (int k = 0; k < 5 * 20; ++k, x += 8) {
      const double bx = x + 1.0;  // exact: radii 0.5 + 0.5
      const auto K = Kind(k % 5);
      const double inf = std::numeric_limits<double>::infinity();
      const float f = float(bx);
      const double ulp32 = double(std::nextafter(f, float(inf))) - double(f);
      const double b = K == exact    ? bx
                       : K == up64   ? std::nextafter(bx, inf)
                       : K == down64 ? std::nextafter(bx, -inf)
                       : K == up32   ? bx + ulp32
                                     : bx - ulp32;
      s.add(x, base, base, 0.5);
      s.add(b, base, base, 0.5);
      kind.push_back(K);
    }
    auto check = [&](auto c, const char* mode) {
      std::vector<bool> found(kind.size(), false);
      for (std::size_t k = 0; k < c.size(); ++k) {
        ASSERT_EQ(c.id_b[k], c.id_a[k] + 1) << mode;
        found[std::size_t(c.id_a[k] / 2)] = true;
      }
      for (std::size_t p = 0; p < kind.size(); ++p) {
        if (kind[p] == up32) {
          EXPECT_FALSE(found[p]) << mode << " " << s.name << " pair " << p;
        }
        if (kind[p] == down32) {
          EXPECT_TRUE(found[p]) << mode << " " << s.name << " pair " << p;
        }
      }
    };
    check(this->template run<double>(s, Precision::fp64), "fp64");
    check(this->template run<double>(s, Precision::mixed), "mixed");
    // fp32's band, 16·ε32·(extent + 2·r_max) ≈ 1.5e-3 here, holds float's ulp near 70 but not at 1e6
    if (base > 1e5) check(this->template run<float>(s, Precision::fp32), "fp32");
  }
}

// fp32 refuses, with the reason, scenes whose float32 world positions would be off by more than a
// quarter of the largest radius (1e8: spacing 8); 1e6 (spacing 0.0625) runs. mixed handles both.
TYPED_TEST(PrecisionTest, Fp32RefusesFarOffsetsItCannotWrite) {
  const Spheres near = random_spheres(3000, 0.5, 1.0, 1331).translated({1e6, 1e6, 1e6});
  const Spheres far = random_spheres(3000, 0.5, 1.0, 1331).translated({1e8, 1e8, 1e8});
  EXPECT_GT(this->template run<float>(near, Precision::fp32).size(), 0u);
  try {
    this->template run<float>(far, Precision::fp32);
    ADD_FAILURE() << "fp32 at 1e8 was not refused";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("use --precision mixed or fp64"), std::string::npos) << e.what();
  }
  const Contacts<double> mixed = this->template run<double>(far, Precision::mixed);
  const Contacts<double> fp64 = this->template run<double>(far, Precision::fp64);
  EXPECT_EQ(mixed.size(), reference_contacts(far.p, far.r).size());
  EXPECT_EQ(compare_contacts(mixed, fp64), "identical");
}

// CUDA = CPU bit for bit in every mode (fp32 with its fp64 rows, mixed's rejecting narrow stage);
// the CPU case checks that one thread and several give the same bits.
TYPED_TEST(PrecisionTest, EveryModeIsBitIdenticalAcrossBackendsAndThreads) {
  const Spheres s = nearly_coincident(1e6, 200, 1341);
  const Backend other = Backend::cpu;
  const int threads = TypeParam::backend == Backend::cuda ? 0 : 1;
  const Contacts<float> f32 = this->template run<float>(s, Precision::fp32);
  const std::uint64_t fp64_rows = this->m_stats.fp64_rows;
  EXPECT_GT(fp64_rows, 0u);
  EXPECT_EQ(compare_contacts(f32, this->template run<float>(s, Precision::fp32, other, threads)),
            "identical");
  EXPECT_EQ(this->m_stats.fp64_rows, fp64_rows);
  for (Precision mode : {Precision::fp64, Precision::mixed})
    EXPECT_EQ(compare_contacts(this->template run<double>(s, mode),
                               this->template run<double>(s, mode, other, threads)),
              "identical")
        << to_string(mode);
}

// mixed's float pre-test (touch_fp64, core/narrow.hpp), checked against its derivation: pairs placed
// at ra + rb + k·m from each other (m = broad_margin, k from −8 to 8, and ±1 ulp of the touching
// distance), at offsets 0 … 1e6 from the origin and radii 1e-3 … 1. With the broad phase's floats
// (packed as pack does: float(world − origin), float(r) + float(m)) every decision is fp64's without
// them; and the floats alone settle every pair farther than 5m from touching: with the world doubles
// poisoned so that they would give the other answer (NaN: apart; all centres at 0: touching).
TEST(MixedPreTest, FloatsSettleExactlyFp64sDecision) {
  std::mt19937_64 rng(4243);
  std::uniform_real_distribution<double> u01(0, 1);
  std::normal_distribution<double> g;
  const double ks[] = {-8, -6, -5, -4.5, -4, -3.5, -3, -2, -1, -0.5, 0, 0.5, 1, 2, 3, 3.5, 4, 4.5, 5, 6, 8};
  std::size_t settled = 0, checked = 0;
  for (double base : {0.0, 3.0, 1e3, 1e6}) {
    for (double rmax : {1e-3, 0.1, 1.0}) {
      const double extent = 200 * rmax;
      // first the radii and centres of A, then B at the distances; m depends on the bounds
      struct Pair {
        Vec3<double> a, dir;
        double ra, rb, k;
        int ulp;
      };
      std::vector<Pair> pairs;
      for (int rep = 0; rep < 40; ++rep)
        for (int j = 0; j < int(std::size(ks)) + 2; ++j) {
          Vec3<double> dir{g(rng), g(rng), g(rng)};
          dir = (1 / std::sqrt(dot(dir, dir))) * dir;
          const Vec3<double> a{base + extent * u01(rng), base + extent * u01(rng), base + extent * u01(rng)};
          const bool ulp = j >= int(std::size(ks));
          pairs.push_back({a, dir, rmax * (0.1 + 0.9 * u01(rng)), rmax * (0.1 + 0.9 * u01(rng)),
                           ulp ? 0.0 : ks[j], ulp ? (j % 2 ? 1 : -1) : 0});
        }
      Bounds b;
      b.lo = b.hi = pairs[0].a;
      b.r_max = rmax;
      b.count = 2 * pairs.size();
      for (const Pair& p : pairs)
        for (double sign : {-1.0, 1.0}) {
          const Vec3<double> c = p.a + (sign * 2 * rmax) * p.dir;  // covers B
          for (const Vec3<double>& v : {p.a, c}) {
            b.lo = {std::min(b.lo.x, v.x), std::min(b.lo.y, v.y), std::min(b.lo.z, v.z)};
            b.hi = {std::max(b.hi.x, v.x), std::max(b.hi.y, v.y), std::max(b.hi.z, v.z)};
          }
        }
      const Vec3<double> origin = b.lo;
      const double m = broad_margin(b, origin, Precision::mixed);
      ASSERT_GT(m, 0);
      std::vector<double> pos, rad;
      for (const Pair& p : pairs) {
        double d = p.ra + p.rb + p.k * m;
        if (p.ulp) d = std::nextafter(p.ra + p.rb, p.ulp > 0 ? 1e300 : 0.0);
        const Vec3<double> bc = p.a + d * p.dir;
        for (const Vec3<double>& v : {p.a, bc}) {
          ASSERT_TRUE(v.x >= b.lo.x && v.x <= b.hi.x && v.y >= b.lo.y && v.y <= b.hi.y && v.z >= b.lo.z &&
                      v.z <= b.hi.z);
          pos.insert(pos.end(), {v.x, v.y, v.z});
        }
        rad.insert(rad.end(), {p.ra, p.rb});
      }
      std::vector<Sphere<float>> broad;
      for (std::size_t i = 0; i < rad.size(); ++i)
        broad.push_back({float(pos[3 * i] - origin.x), float(pos[3 * i + 1] - origin.y),
                         float(pos[3 * i + 2] - origin.z), float(rad[i]) + float(m)});
      const std::vector<double> nan_pos(pos.size(), std::numeric_limits<double>::quiet_NaN()),
          zero_pos(pos.size(), 0.0);
      const NarrowBodies<double> plain{nullptr, pos.data(), rad.data(), origin};
      NarrowBodies<double> with_floats = plain, nan_doubles = plain, zero_doubles = plain;
      for (NarrowBodies<double>* w : {&with_floats, &nan_doubles, &zero_doubles}) {
        w->broad = broad.data();
        w->broad_margin = float(m);
      }
      nan_doubles.position = nan_pos.data();
      zero_doubles.position = zero_pos.data();
      for (std::size_t p = 0; p < pairs.size(); ++p) {
        const auto a = std::uint32_t(2 * p), bb = std::uint32_t(2 * p + 1);
        const bool fp64 = touch_fp64(plain, a, bb);
        ASSERT_EQ(touch_fp64(with_floats, a, bb), fp64)
            << "base " << base << " rmax " << rmax << " k " << pairs[p].k << " ulp " << pairs[p].ulp;
        ++checked;
        if (pairs[p].ulp || pairs[p].ra + pairs[p].rb <= 8 * m) continue;
        if (pairs[p].k <= -5) {
          EXPECT_TRUE(fp64);
          EXPECT_TRUE(touch_fp64(nan_doubles, a, bb)) << "k " << pairs[p].k << " not settled on the floats";
          ++settled;
        } else if (pairs[p].k >= 5) {
          EXPECT_FALSE(fp64);
          EXPECT_FALSE(touch_fp64(zero_doubles, a, bb)) << "k " << pairs[p].k << " not settled on the floats";
          ++settled;
        }
      }
    }
  }
  EXPECT_GT(settled, checked / 10);
}

}  // namespace
}  // namespace cg::test
