// Ellipsoid and sphere–ellipsoid contacts (kernels/core/ellipsoid_contact.hpp, issue #12) against the
// exact long-double reference of src/reference/ellipsoid_reference.hpp, which shares no code with it.
// The tolerances and the checks against the reference are in ellipsoid_pairs.hpp, with the pieces the
// tests share; the certificates of globality are test_ellipsoid_certificates.cpp, the start set and how
// its runs are taken test_ellipsoid_start_set.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "core/centre_cut.hpp"
#include "core/contact.hpp"
#include "core/ellipsoid_contact.hpp"
#include "core/quat.hpp"
#include "core/shape_narrow.hpp"
#include "ellipsoid_pairs.hpp"
#include "reference/ellipsoid_reference.hpp"

namespace cg::test {
namespace {

TYPED_TEST_SUITE(EllipsoidContactTest, Reals);

// Random pairs: centre distance U[0, 1.1]·s, so overlaps from coincident to just apart.
TYPED_TEST(EllipsoidContactTest, RandomPairsAgainstReference) {
  using Real = TypeParam;
  for (double aspect : {1.5, 3.0, 10.0, 100.0}) {
    Stats st;
    st.name = tag<Real>("random 1:" + std::to_string(int(aspect)));
    std::mt19937_64 rng(1000 + int(aspect));
    std::uniform_real_distribution<double> u(0, 1.1);
    const int n = aspect >= 100 ? 100 : 120;
    for (int i = 0; i < n; ++i) {
      Body<Real> b{
          {Real(0.1), Real(-0.2), Real(0.3)}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
      Body<Real> a{{}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
      const Vec3<double> d = random_unit(rng);
      const double len = u(rng) * double(scale_of(a, b));
      a.centre = {Real(b.centre.x + len * d.x), Real(b.centre.y + len * d.y), Real(b.centre.z + len * d.z)};
      check_against_reference(a, b, solve(a, b), st);
    }
    st.print();
  }
}

// Touching by construction: for a random n, a = b + ∇h_A(n) + ∇h_B(n) (computed in long double) puts
// the support points of A at −n and of B at n on top of each other with the common normal n: the exact
// distance is 0 up to the rounding of a to Real. The engine's |distance| must stay inside the band.
TYPED_TEST(EllipsoidContactTest, TouchingPairs) {
  using Real = TypeParam;
  for (double aspect : {1.0001, 3.0, 10.0, 100.0}) {
    Stats st;
    st.name = tag<Real>("touching 1:" + std::to_string(int(aspect)));
    std::mt19937_64 rng(2000 + int(aspect));
    double max_abs = 0;
    for (int i = 0; i < 200; ++i) {
      auto [a, b, n, off] = touching_pair<Real>(rng, aspect);
      a.centre = {Real(LD(b.centre.x) + off.x), Real(LD(b.centre.y) + off.y), Real(LD(b.centre.z) + off.z)};
      const EllipsoidContact<Real> c = solve(a, b);
      const double s = double(scale_of(a, b));
      max_abs = std::max(max_abs, std::abs(double(c.geometry.distance)) / s);
      EXPECT_LE(std::abs(double(c.geometry.distance)), Tol<Real>::dist * s) << st.name;
      // the independent PW value is 1 to the rounding of the centres
      const LD pw = exact::pw_exact(reference_pair(a, b));
      EXPECT_NEAR(double(pw), 1.0, (std::is_same_v<Real, float> ? 1e-5 * aspect : 1e-12 * aspect)) << st.name;
      EXPECT_NEAR(double(c.pw), 1.0,
                  (std::is_same_v<Real, float> ? 2e-3 * aspect * aspect : 1e-9 * aspect * aspect))
          << st.name;
      check_against_reference(a, b, c, st, 4000);
    }
    st.print();
    std::printf("[ellipsoid] %-28s max |distance|/s at touching %.2e (band %.0e)\n", st.name.c_str(), max_abs,
                Tol<Real>::dist);
  }
}

// The centre-line pre-test (ellipsoid_contact.hpp: separated_along_centres) rejects only pairs that
// are apart — by the exact long-double Perram–Wertheim function — and most of the apart ones among
// bounding-sphere candidates, including pairs placed a hair apart along the centre line.
TYPED_TEST(EllipsoidContactTest, CentreLineRejectsOnlyPairsApart) {
  using Real = TypeParam;
  std::mt19937_64 rng(2718);
  std::uniform_real_distribution<double> u(-2, 2);
  int candidates = 0, apart = 0, rejected = 0;
  for (int i = 0; i < 4000; ++i) {
    const double aspect = i % 2 ? 4.0 : 10.0;
    Body<Real> a{{}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
    Body<Real> b{
        {Real(u(rng)), Real(u(rng)), Real(u(rng))}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
    if (i % 8 == 0) {  // a hair apart along the centre line: |a − b| = h_A(u) + h_B(u) (1 + 1e-5)
      const exact::Pair p = reference_pair(a, b);
      const LD len = std::sqrt(exact::dotp(p.r, p.r));
      const exact::V dir{p.r.x / len, p.r.y / len, p.r.z / len};
      const LD reach = exact::support_value(p.a, dir) + exact::support_value(p.b, dir);
      const LD s = reach * LD(1 + 1e-5) / len;
      b.centre = {Real(LD(b.centre.x) * s), Real(LD(b.centre.y) * s), Real(LD(b.centre.z) * s)};
    }
    const Ellipsoid<Real> ea = engine_body(a), eb = engine_body(b);
    const Vec3<Real> d = ea.centre - eb.centre;
    if (std::sqrt(double(dot(d, d))) > double(scale_of(a, b))) continue;  // bounding spheres apart
    ++candidates;
    const LD pw = exact::pw_exact(reference_pair(a, b));
    apart += pw > 1;
    if (!separated_along_centres(ea, eb)) continue;
    ++rejected;
    EXPECT_GT(pw, LD(1)) << tag<Real>("") << " pair " << i << ": rejected but not apart";
  }
  std::printf("[ellipsoid] %s centre line: %d candidates, %d apart, %d rejected before PW\n",
              tag<Real>("").c_str(), candidates, apart, rejected);
  EXPECT_GE(rejected, apart * 3 / 4) << "the centre line should reject most pairs that are apart";
}

// The pair stage's centre cut (core/centre_cut.hpp) cuts only pairs that the narrow stage's own
// centre-line test rejects in the narrow's frame — fp32: the same local floats; fp64 and mixed: the world
// difference of the doubles and fp64's packed shapes (also fp32's pairs in fp64) — and that the exact
// long-double PW function finds apart: in the three precision modes (Broad, Narrow), at aspect ratios
// 1:4, 1:10 and 1:100, with large local coordinates (a big scene's far corner) and pairs placed a hair
// apart along the centre line around the cut's margin. It must also cut most of what that test rejects.
template <class Broad, class Narrow>
void check_centre_cut(const char* mode, std::initializer_list<double> offsets) {
  std::mt19937_64 rng(1618);
  std::uniform_real_distribution<double> u(-2, 2);
  const double hairs[] = {1e-5, 5e-4, 1.5e-3, 4e-3};
  for (double offset : offsets) {
    int candidates = 0, centre_line = 0, cut = 0, random_line = 0, random_cut = 0;  // random: no hairs
    for (int i = 0; i < 3000; ++i) {
      const double aspect = i % 3 == 0 ? 4.0 : (i % 3 == 1 ? 10.0 : 100.0);
      Body<double> a{{offset + u(rng), offset * 0.5 + u(rng), -offset + u(rng)},
                     random_axes<double>(rng, aspect),
                     random_quat<double>(rng)};
      Body<double> b{
          {offset, offset * 0.5, -offset}, random_axes<double>(rng, aspect), random_quat<double>(rng)};
      if (i % 4 == 0) {  // a hair apart along the centre line: |a − b| = reach (1 + hair)
        const exact::Pair p = reference_pair(a, b);
        const LD len = std::sqrt(exact::dotp(p.r, p.r));
        const exact::V dir{p.r.x / len, p.r.y / len, p.r.z / len};
        const LD reach = exact::support_value(p.a, dir) + exact::support_value(p.b, dir);
        const LD s = reach * LD(1 + hairs[(i / 4) % 4]) / len;
        a.centre = {double(LD(b.centre.x) + p.r.x * s), double(LD(b.centre.y) + p.r.y * s),
                    double(LD(b.centre.z) + p.r.z * s)};
      }
      auto packed = [](const Body<double>& x) {
        const double semi[3] = {x.axes.x, x.axes.y, x.axes.z}, q[4] = {x.q.w, x.q.x, x.q.y, x.q.z};
        return pack_shape<Narrow>(static_cast<std::uint8_t>(Shape::ellipsoid), semi, q);
      };
      auto sphere = [](const Body<double>& x) {  // the pair stage's: local Broad centre, bounding radius
        const double r = std::max(x.axes.x, std::max(x.axes.y, x.axes.z));
        return Sphere<Broad>{Broad(x.centre.x), Broad(x.centre.y), Broad(x.centre.z), Broad(r)};
      };
      const PackedShape<Narrow> pa = packed(a), pb = packed(b);
      const Sphere<Broad> sa = sphere(a), sb = sphere(b);
      if (!spheres_touch(sa, sb)) continue;
      ++candidates;
      // the narrow's frame and its centre-line test (ShapeDecide::screen / ellipsoid_contact)
      bool narrow_rejects;
      if constexpr (std::is_same_v<Narrow, float>) {
        narrow_rejects = separated_along_centres(ellipsoid_of(sa, pa), ellipsoid_of(sb, pb));
      } else {
        const Sphere<double> fa{a.centre.x - b.centre.x, a.centre.y - b.centre.y, a.centre.z - b.centre.z, 0},
            fb{0, 0, 0, 0};
        narrow_rejects = separated_along_centres(ellipsoid_of(fa, pa), ellipsoid_of(fb, pb));
      }
      // fp32's pairs in fp64 (any pair may be one): fp64's frame and packed shapes
      const Sphere<double> wa{a.centre.x - b.centre.x, a.centre.y - b.centre.y, a.centre.z - b.centre.z, 0};
      const bool fp64_rejects = separated_along_centres(
          ellipsoid_of(wa, packed_double(a)), ellipsoid_of(Sphere<double>{0, 0, 0, 0}, packed_double(b)));
      centre_line += narrow_rejects;
      random_line += narrow_rejects && i % 4 != 0;
      if (!cut_apart(sa, sb, cut_shape(pa), cut_shape(pb))) continue;
      ++cut;
      random_cut += i % 4 != 0;
      EXPECT_TRUE(narrow_rejects) << mode << " offset " << offset << " pair " << i
                                  << ": cut, narrow keeps it";
      EXPECT_TRUE(fp64_rejects) << mode << " offset " << offset << " pair " << i << ": cut, fp64 keeps it";
      EXPECT_GT(exact::pw_exact(reference_pair(a, b)), LD(1)) << mode << " pair " << i << ": cut, not apart";
    }
    std::printf(
        "[ellipsoid] %s centre cut, offset %g: %d candidates, %d rejected by the narrow's centre line "
        "(%d of them placed at random), %d cut (%d)\n",
        mode, offset, candidates, centre_line, random_line, cut, random_cut);
    // near the origin the margin costs little: nearly every random pair the centre line rejects is cut
    if (offset == 0.0) {
      EXPECT_GE(random_cut, random_line * 9 / 10) << mode << ": the cut should take most";
    }
  }
}

TEST(CentreCut, CutsOnlyPairsTheNarrowRejects) {
  check_centre_cut<float, float>("fp32", {0.0, 1e2, 1e4});
  check_centre_cut<float, double>("mixed", {0.0, 1e2, 1e4});
  check_centre_cut<double, double>("fp64", {0.0, 1e6, 1e9});
}

// The box of each shape (cut_box, the half-extents of cut_cells: core/centre_cut.hpp) holds the body —
// its exact reach along each axis from its exact centre — with room to spare for the narrow's own
// rounding (2^-11 of the bounding radius beyond the broad phase's centre error) unless it is the bounding
// sphere's box, in the three modes, at aspect ratios 1:4, 1:10 and 1:100 and far from the origin; never
// wider than the bounding radius; and on average well inside it (the cells' gain).
template <class Broad, class Narrow>
void check_shape_boxes(const char* mode, std::initializer_list<double> offsets) {
  std::mt19937_64 rng(2718);
  std::uniform_real_distribution<double> u(-2, 2);
  for (double offset : offsets) {
    double share = 0;  // mean half-extent / bounding radius
    int bodies = 0;
    for (int i = 0; i < 3000; ++i) {
      const double aspect = i % 3 == 0 ? 4.0 : (i % 3 == 1 ? 10.0 : 100.0);
      const Body<double> x{{offset + u(rng), offset * 0.5 + u(rng), -offset + u(rng)},
                           random_axes<double>(rng, aspect),
                           random_quat<double>(rng)};
      const double semi[3] = {x.axes.x, x.axes.y, x.axes.z}, q[4] = {x.q.w, x.q.x, x.q.y, x.q.z};
      const PackedShape<Narrow> p = pack_shape<Narrow>(static_cast<std::uint8_t>(Shape::ellipsoid), semi, q);
      const double r = std::max(x.axes.x, std::max(x.axes.y, x.axes.z));
      const Sphere<Broad> s{Broad(x.centre.x), Broad(x.centre.y), Broad(x.centre.z), Broad(r)};
      const Vec3<Broad> e = cut_box(s, cut_shape(p), Broad(0));
      const exact::Body ex = reference_body(x);
      const LD half[3] = {LD(e.x), LD(e.y), LD(e.z)};
      const LD centre_error[3] = {std::fabs(LD(s.x) - LD(x.centre.x)), std::fabs(LD(s.y) - LD(x.centre.y)),
                                  std::fabs(LD(s.z) - LD(x.centre.z))};
      for (int k = 0; k < 3; ++k) {
        const exact::V axis{LD(k == 0), LD(k == 1), LD(k == 2)};
        const LD reach = exact::support_value(ex, axis);
        if (half[k] < LD(s.r)) {  // (else the bounding sphere's box, as without the cut)
          EXPECT_GE(half[k], reach + centre_error[k] + LD(r) * LD(0x1p-11))
              << mode << " offset " << offset << " body " << i << " axis " << k;
        }
        EXPECT_LE(half[k], LD(s.r)) << mode << " body " << i;
        share += double(half[k]) / r / 3;
      }
      ++bodies;
    }
    std::printf("[ellipsoid] %s shape boxes, offset %g: half-extent %.3f of the bounding radius\n", mode,
                offset, share / bodies);
    if (offset == 0.0) {
      EXPECT_LT(share / bodies, 0.85) << mode << ": the boxes should be well inside the bounding spheres";
    }
  }
}

TEST(CentreCut, ShapeBoxesHoldTheShapes) {
  check_shape_boxes<float, float>("fp32", {0.0, 1e2, 1e4});
  check_shape_boxes<float, double>("mixed", {0.0, 1e2, 1e4});
  check_shape_boxes<double, double>("fp64", {0.0, 1e6, 1e9});
}

// The cut leaves spheres, ellipsoids with three equal semi-axes (the sphere–ellipsoid path, which has no
// centre-line test) and any pair with one of them alone, however far apart along the centre line.
TEST(CentreCut, LeavesPairsWithoutTheGeneralSolve) {
  const double semi[3] = {1, 0.5, 0.25}, round[3] = {0.5, 0.5, 0.5}, q[4] = {1, 0, 0, 0};
  const PackedShape<float> ell = pack_shape<float>(1, semi, q), eq = pack_shape<float>(1, round, q),
                           sph = pack_shape<float>(0, semi, q);
  const Sphere<float> sa{0, 0, 0, 1}, sb{0, 0, 1.9f, 1};  // bounding spheres touch; the shapes are apart
  EXPECT_TRUE(cut_apart(sa, sb, cut_shape(ell), cut_shape(ell)));
  for (const PackedShape<float>& other : {eq, sph}) {
    EXPECT_FALSE(cut_apart(sa, sb, cut_shape(ell), cut_shape(other)));
    EXPECT_FALSE(cut_apart(sa, sb, cut_shape(other), cut_shape(ell)));
  }
  EXPECT_FALSE(cut_apart(sa, sa, cut_shape(ell), cut_shape(ell))) << "coincident centres";
  for (const PackedShape<float>& other : {eq, sph}) {  // their cells: the bounding sphere's box
    const Vec3<float> e = cut_box(sb, cut_shape(other), 0.0f);
    EXPECT_EQ(e.x, sb.r);
    EXPECT_EQ(e.y, sb.r);
    EXPECT_EQ(e.z, sb.r);
  }
}

// A centre inside the other body.
TYPED_TEST(EllipsoidContactTest, DeepPenetration) {
  using Real = TypeParam;
  for (double aspect : {2.0, 10.0, 100.0}) {
    Stats st;
    st.name = tag<Real>("deep 1:" + std::to_string(int(aspect)));
    std::mt19937_64 rng(3000 + int(aspect));
    std::uniform_real_distribution<double> u(0, 0.95);
    for (int i = 0; i < 100; ++i) {
      Body<Real> b{{Real(-0.5), Real(0.25), Real(1)}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
      Body<Real> a{{}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
      const Vec3<double> d = random_unit(rng);
      const double t = u(rng);
      const Vec3<Real> local{Real(t * d.x * b.axes.x), Real(t * d.y * b.axes.y), Real(t * d.z * b.axes.z)};
      a.centre = b.centre + mul(rotation_matrix(b.q), local);
      check_against_reference(a, b, solve(a, b), st);
    }
    st.print();
  }
}

// Crossed needles: long axes nearly perpendicular, centres offset along the common perpendicular and
// sideways; f has several local minima (out along either needle's thin direction, or along the other's
// long one) and the engine must find the global one.
TYPED_TEST(EllipsoidContactTest, CrossedNeedles) {
  using Real = TypeParam;
  for (double aspect : {10.0, 100.0}) {
    Stats st;
    st.name = tag<Real>("crossed needles 1:" + std::to_string(int(aspect)));
    std::mt19937_64 rng(4000 + int(aspect));
    std::uniform_real_distribution<double> u(-1, 1);
    for (int i = 0; i < 100; ++i) {
      const Real thin = Real(1.0 / aspect);
      const Quat<Real> base = random_quat<Real>(rng);
      // B along base·x; A along base·y, tilted by up to 15°
      const double tilt = 0.26 * u(rng);
      const Quat<Real> zrot{Real(std::cos(kPi / 4 + tilt / 2)), 0, 0, Real(std::sin(kPi / 4 + tilt / 2))};
      auto qmul = [](Quat<Real> p, Quat<Real> q) {
        return Quat<Real>{
            p.w * q.w - p.x * q.x - p.y * q.y - p.z * q.z, p.w * q.x + p.x * q.w + p.y * q.z - p.z * q.y,
            p.w * q.y - p.x * q.z + p.y * q.w + p.z * q.x, p.w * q.z + p.x * q.y - p.y * q.x + p.z * q.w};
      };
      Body<Real> b{{Real(0.3), Real(0.1), Real(-0.2)},
                   {Real(1), thin, Real(thin * (1 + 0.5 * std::abs(u(rng))))},
                   base};
      Body<Real> a{{}, {Real(1), Real(thin * (1 + 0.5 * std::abs(u(rng)))), thin}, qmul(base, zrot)};
      const Mat3<Real> rb = rotation_matrix(base);
      const Vec3<Real> off{Real(0.6 * u(rng)), Real(0.6 * u(rng)), Real(1.5 * thin * u(rng))};
      a.centre = b.centre + mul(rb, off);
      check_against_reference(a, b, solve(a, b), st, 16000);
    }
    st.print();
    EXPECT_GT(st.multi_minima, 0) << "the crossed-needle set should contain pairs with several local minima";
  }
}

// Coincident centres: deterministic (same answer twice), canonical sign, the depth of the reference.
TYPED_TEST(EllipsoidContactTest, CoincidentCentres) {
  using Real = TypeParam;
  Stats st;
  st.name = tag<Real>("coincident centres");
  std::mt19937_64 rng(5000);
  for (int i = 0; i < 60; ++i) {
    Body<Real> b{
        {Real(0.5), Real(0.5), Real(0.5)}, random_axes<Real>(rng, 1 + i % 7), random_quat<Real>(rng)};
    Body<Real> a{b.centre, random_axes<Real>(rng, 1 + i % 5), random_quat<Real>(rng)};
    const EllipsoidContact<Real> c1 = solve(a, b), c2 = solve(a, b);
    EXPECT_TRUE(c1.geometry.normal_on_b == c2.geometry.normal_on_b);
    EXPECT_EQ(c1.geometry.distance, c2.geometry.distance);
    const Vec3<Real> n = c1.geometry.normal_on_b;
    const Real first = n.x != 0 ? n.x : (n.y != 0 ? n.y : n.z);
    EXPECT_GT(first, Real(0)) << "canonical sign";
    // depth only: ±n are both minimisers, the reference may return either
    const exact::Reference ref = exact::exact_contact(reference_pair(a, b), 8000);
    const double s = double(scale_of(a, b));
    const double derr = std::abs(double(c1.geometry.distance) - double(ref.distance)) / s;
    st.max_dist_err = std::max(st.max_dist_err, derr);
    ++st.pairs;
    st.evaluations += c1.iterations;
    st.max_evaluations = std::max(st.max_evaluations, c1.iterations);
    st.nonconverged += !c1.converged;
    EXPECT_LE(derr, Tol<Real>::dist);
    check_self_consistency(a, b, c1, st);
  }
  st.print();
  // sphere–ellipsoid with coincident centres: the same canonical sign, depth ρ + smallest semi-axis
  for (int i = 0; i < 20; ++i) {
    Body<Real> e{{Real(0.5), Real(-1), Real(2)}, random_axes<Real>(rng, 4), random_quat<Real>(rng)};
    const Sphere<Real> sp{e.centre.x, e.centre.y, e.centre.z, Real(0.3)};
    for (bool sphere_is_a : {true, false}) {
      const EllipsoidContact<Real> c = sphere_ellipsoid_contact(sp, engine_body(e), sphere_is_a);
      const Vec3<Real> n = c.geometry.normal_on_b;
      const Real first = n.x != 0 ? n.x : (n.y != 0 ? n.y : n.z);
      EXPECT_GT(first, Real(0)) << "canonical sign, sphere–ellipsoid";
      const Real emin = std::min(e.axes.x, std::min(e.axes.y, e.axes.z));
      EXPECT_NEAR(double(c.geometry.distance), -double(Real(0.3) + emin),
                  4 * std::numeric_limits<Real>::epsilon());
    }
  }
  // two spheres keep n = (1, 0, 0)
  const Ellipsoid<Real> s1 = make_ellipsoid<Real>({1, 2, 3}, {Real(0.5), Real(0.5), Real(0.5)}, {1, 0, 0, 0});
  const Ellipsoid<Real> s2 =
      make_ellipsoid<Real>({1, 2, 3}, {Real(0.7), Real(0.7), Real(0.7)}, {Real(0.6), 0, Real(0.8), 0});
  const auto r = ellipsoid_contact(s1, s2);
  EXPECT_EQ(r.contact.geometry.normal_on_b.x, Real(1));
  EXPECT_EQ(r.contact.geometry.distance, Real(-1.2));
  const auto g = ellipsoid_pair_contact(s1, s2, perram_wertheim(s1, s2));
  EXPECT_EQ(g.geometry.normal_on_b.x, Real(1));
  EXPECT_NEAR(double(g.geometry.distance), -1.2, 8 * std::numeric_limits<Real>::epsilon());
}

// Equal semi-axes: the dispatch is bitwise sphere_sphere_contact; the general solver agrees to rounding.
TYPED_TEST(EllipsoidContactTest, EqualSemiAxesAreSpheres) {
  using Real = TypeParam;
  std::mt19937_64 rng(6000);
  std::uniform_real_distribution<double> u(0.5, 1.0), pos(-2, 2);
  const double eps = std::numeric_limits<Real>::epsilon();
  double max_err = 0;
  for (int i = 0; i < 500; ++i) {
    const Real ra = Real(u(rng)), rb = Real(u(rng));
    const Vec3<Real> ca{Real(pos(rng)), Real(pos(rng)), Real(pos(rng))},
        cb{Real(pos(rng)), Real(pos(rng)), Real(pos(rng))};
    const Ellipsoid<Real> a = make_ellipsoid(ca, {ra, ra, ra}, random_quat<Real>(rng));
    const Ellipsoid<Real> b = make_ellipsoid(cb, {rb, rb, rb}, random_quat<Real>(rng));
    const ContactGeometry<Real> want =
        sphere_sphere_contact(Sphere<Real>{ca.x, ca.y, ca.z, ra}, Sphere<Real>{cb.x, cb.y, cb.z, rb});
    const auto got = ellipsoid_contact(a, b);
    EXPECT_TRUE(got.contact.geometry.position_on_a == want.position_on_a);
    EXPECT_TRUE(got.contact.geometry.position_on_b == want.position_on_b);
    EXPECT_TRUE(got.contact.geometry.normal_on_b == want.normal_on_b);
    EXPECT_EQ(got.contact.geometry.distance, want.distance);
    EXPECT_EQ(got.in_contact,
              spheres_touch(Sphere<Real>{ca.x, ca.y, ca.z, ra}, Sphere<Real>{cb.x, cb.y, cb.z, rb}));
    const auto gen = ellipsoid_pair_contact(a, b, perram_wertheim(a, b));
    auto d = [](Vec3<Real> p, Vec3<Real> q) { return std::sqrt(double(dot(p - q, p - q))); };
    const double e = std::max({d(gen.geometry.position_on_a, want.position_on_a),
                               d(gen.geometry.position_on_b, want.position_on_b),
                               d(gen.geometry.normal_on_b, want.normal_on_b),
                               std::abs(double(gen.geometry.distance - want.distance))});
    max_err = std::max(max_err, e);
    EXPECT_LE(e, 64 * eps * 4) << "general path vs closed form";
    // the sphere–ellipsoid path with a sphere given as a true Sphere
    const auto se = sphere_ellipsoid_contact(Sphere<Real>{ca.x, ca.y, ca.z, ra}, b, true);
    EXPECT_TRUE(se.geometry.position_on_b == want.position_on_b);
    EXPECT_EQ(se.geometry.distance, want.distance);
  }
  std::printf("[ellipsoid] %-28s general solver vs closed form: max error %.2e (= %.1f eps)\n",
              tag<Real>("equal semi-axes").c_str(), max_err, max_err / eps);
}

// Far from the origin: the engine works on centre differences; a pair at 1e6 gives the pair at the
// origin shifted, to the rounding of the 1e6 coordinates (double only: fp32 runs in the engine's local
// frame).
TEST(EllipsoidContactFar, OffsetByAMillion) {
  std::mt19937_64 rng(7000);
  std::uniform_real_distribution<double> u(0, 1.0);
  double max_err = 0;
  for (int i = 0; i < 200; ++i) {
    Body<double> b{{0, 0, 0}, random_axes<double>(rng, 5), random_quat<double>(rng)};
    Body<double> a{{}, random_axes<double>(rng, 5), random_quat<double>(rng)};
    const Vec3<double> d = random_unit(rng);
    const double len = u(rng) * scale_of(a, b);
    a.centre = {len * d.x, len * d.y, len * d.z};
    const Vec3<double> off{1e6 + 0.375, -2e6 + 0.125, 3e6 - 0.5};
    Body<double> a2 = a, b2 = b;
    a2.centre = a.centre + off;
    b2.centre = b.centre + off;
    const auto c0 = solve(a, b), c1 = solve(a2, b2);
    // the centre difference of the shifted pair is exact only to 1e6·eps: compare with that in mind
    const double tol = 3e6 * std::numeric_limits<double>::epsilon() * 64;
    const Vec3<double> dp = c1.geometry.position_on_a - (c0.geometry.position_on_a + off);
    max_err = std::max(max_err, std::sqrt(dot(dp, dp)));
    EXPECT_LE(std::sqrt(dot(dp, dp)), tol);
    EXPECT_NEAR(c1.geometry.distance, c0.geometry.distance, tol);
    Stats st;
    st.name = "far";
    check_self_consistency(a2, b2, c1, st);
  }
  std::printf("[ellipsoid] far from origin (1e6, fp64): max position shift error %.2e\n", max_err);
}

// Sphere–ellipsoid: the 1-D root find against the general solver (sphere as an ellipsoid with equal
// axes) and against the reference, both orders (sphere as A and as B), inside and outside.
TYPED_TEST(EllipsoidContactTest, SphereEllipsoidMatchesGeneralPath) {
  using Real = TypeParam;
  for (double aspect : {2.0, 10.0, 100.0}) {
    Stats st, sg;
    st.name = tag<Real>("sphere-ellipsoid 1:" + std::to_string(int(aspect)));
    sg.name = tag<Real>("  same, general solver");
    std::mt19937_64 rng(8000 + int(aspect));
    std::uniform_real_distribution<double> u(0, 1.1), ru(0.05, 1.0);
    double max_diff = 0;
    for (int i = 0; i < 100; ++i) {
      const Real rho = Real(ru(rng));
      Body<Real> e{
          {Real(0.2), Real(0.4), Real(-0.6)}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
      Body<Real> s{{}, {rho, rho, rho}, {1, 0, 0, 0}};
      const Vec3<double> d = random_unit(rng);
      const double len = u(rng) * double(scale_of(s, e));
      s.centre = {Real(e.centre.x + len * d.x), Real(e.centre.y + len * d.y), Real(e.centre.z + len * d.z)};
      const bool sphere_is_a = i % 2 == 0;
      const Sphere<Real> sp{s.centre.x, s.centre.y, s.centre.z, rho};
      const EllipsoidContact<Real> c = sphere_ellipsoid_contact(sp, engine_body(e), sphere_is_a);
      const Body<Real>& A = sphere_is_a ? s : e;
      const Body<Real>& B = sphere_is_a ? e : s;
      check_against_reference(A, B, c, st);
      const EllipsoidContact<Real> g = solve(A, B);
      ++sg.pairs;
      sg.evaluations += g.iterations;
      sg.max_evaluations = std::max(sg.max_evaluations, g.iterations);
      sg.nonconverged += !g.converged;
      const double sc = double(scale_of(A, B));
      const double dd = std::abs(double(g.geometry.distance - c.geometry.distance)) / sc;
      max_diff = std::max(max_diff, dd);
      EXPECT_LE(dd, 2 * Tol<Real>::dist);
      EXPECT_EQ(c.geometry.distance <= 0,
                g.geometry.distance <= 0 || std::abs(double(c.geometry.distance)) <= Tol<Real>::dist * sc);
    }
    st.print();
    sg.print();
    std::printf("[ellipsoid] %-28s max |d_sphere_path − d_general|/s %.2e\n", st.name.c_str(), max_diff);
  }
}

// The PW filter agrees with the independent long-double PW, and with the reference distance sign.
TYPED_TEST(EllipsoidContactTest, PerramWertheimDecision) {
  using Real = TypeParam;
  std::mt19937_64 rng(9000);
  std::uniform_real_distribution<double> u(0, 1.3);
  double max_rel = 0;
  int rejected = 0, disagree = 0;
  long pw_iters = 0;
  int pw_max = 0;
  const int n = 400;
  for (int i = 0; i < n; ++i) {
    const double aspect = i % 4 == 3 ? 100.0 : 1.0 + (i % 10);
    Body<Real> b{{Real(0.1), Real(0.2), Real(0.3)}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
    Body<Real> a{{}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
    const Vec3<double> d = random_unit(rng);
    const double len = u(rng) * double(scale_of(a, b));
    a.centre = {Real(b.centre.x + len * d.x), Real(b.centre.y + len * d.y), Real(b.centre.z + len * d.z)};
    const Ellipsoid<Real> ea = engine_body(a), eb = engine_body(b);
    const PerramWertheim<Real> pw = perram_wertheim(ea, eb);
    pw_iters += pw.iterations;
    pw_max = std::max(pw_max, pw.iterations);
    const exact::Pair p = reference_pair(a, b);
    const double ref = double(exact::pw_exact(p));
    const double rel = std::abs(double(pw.value) - ref) / ref;
    max_rel = std::max(max_rel, rel);
    EXPECT_LE(rel, double(pw.band)) << "PW outside its stated rounding band, aspect " << aspect;
    if (!pw_may_touch(pw)) {
      ++rejected;
      // a rejected pair is apart: check against the brute-force minimum too
      const exact::Reference r = exact::exact_contact(p, 4000);
      EXPECT_GT(double(r.distance), 0.0);
    }
    // exact PW sign vs exact min f sign (two independent long-double computations)
    if (std::abs(ref - 1) > 1e-9) {
      const exact::Reference r = exact::exact_contact(p, 8000);
      if ((ref < 1) != (r.distance < 0)) ++disagree;
    }
  }
  EXPECT_EQ(disagree, 0);
  std::printf(
      "[ellipsoid] %-28s PW: iterations mean %.1f max %d, max rel. error vs long double %.2e, rejected "
      "%d/%d\n",
      tag<Real>("perram-wertheim").c_str(), double(pw_iters) / n, pw_max, max_rel, rejected, n);
}

}  // namespace
}  // namespace cg::test
