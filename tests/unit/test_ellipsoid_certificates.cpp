// The certificates of globality of the ellipsoid solve (kernels/core/ellipsoid_solve.hpp,
// ellipsoid_certificate.hpp): a certified first minimum is the whole start set's answer, the lemma under
// the two balls' certificate, the eigenvalue bound of the inner-ellipsoid certificate and the deep
// overlaps it settles, each against the exact long-double reference (ellipsoid_pairs.hpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "core/contact.hpp"
#include "core/ellipsoid_contact.hpp"
#include "core/quat.hpp"
#include "core/shape_narrow.hpp"
#include "ellipsoid_pairs.hpp"
#include "reference/ellipsoid_reference.hpp"

namespace cg::test {
namespace {

TYPED_TEST_SUITE(EllipsoidContactTest, Reals);

// The globality certificate (ellipsoid_solve.hpp): a converged minimum n with t = f(n) ≤ e_A²/h_A(n) +
// e_B²/h_B(n) (the radii of the largest balls tangent inside at the two contact points) is the global
// one, so the rest of the start set is skipped. That reach is at least ρ = Σ e_min²/e_max (the old
// rolling-ball bound, which certified only t < ρ/2). Over touching pairs pushed together by depths from
// 0 to well past ρ, and random overlaps, the certified solve must give exactly the bits of the whole
// start set (the other starts would only find the same minimum); shallow pairs and pairs pushed in by
// 0.8ρ (beyond the old bound, within the new one) must stop early (the point of the certificate).
TYPED_TEST(EllipsoidContactTest, CertifiedFirstMinimumIsTheWholeSetsAnswer) {
  using Real = TypeParam;
  SolverSettings<Real> full;
  full.certify = false;
  for (double aspect : {1.5, 4.0, 10.0, 100.0}) {
    std::mt19937_64 rng(7000 + int(aspect));
    int shallow = 0, shallow_early = 0, deep = 0, deep_early = 0;
    long evals_certified = 0, evals_full = 0;
    for (int i = 0; i < 240; ++i) {
      auto [a, b, n, off] = touching_pair<Real>(rng, aspect);
      auto rho_of = [](Vec3<Real> e) {
        const double lo = std::min({double(e.x), double(e.y), double(e.z)});
        return lo * lo / std::max({double(e.x), double(e.y), double(e.z)});
      };
      const double rho = rho_of(a.axes) + rho_of(b.axes);
      // depth along n: i % 6 picks 0, 0.05ρ, 0.2ρ, 0.45ρ (certifiable), 0.8ρ, 3ρ (not)
      const double depth = rho * std::array<double, 6>{0, 0.05, 0.2, 0.45, 0.8, 3.0}[i % 6];
      a.centre = {Real(LD(b.centre.x) + off.x - LD(depth) * n.x),
                  Real(LD(b.centre.y) + off.y - LD(depth) * n.y),
                  Real(LD(b.centre.z) + off.z - LD(depth) * n.z)};
      const Ellipsoid<Real> ea = engine_body(a), eb = engine_body(b);
      const PerramWertheim<Real> pw = perram_wertheim(ea, eb);
      const EllipsoidContact<Real> c = ellipsoid_pair_contact(ea, eb, pw);
      const EllipsoidContact<Real> w = ellipsoid_pair_contact(ea, eb, pw, full);
      const auto& g = c.geometry;
      const auto& h = w.geometry;
      EXPECT_TRUE(g.normal_on_b.x == h.normal_on_b.x && g.normal_on_b.y == h.normal_on_b.y &&
                  g.normal_on_b.z == h.normal_on_b.z && g.distance == h.distance)
          << tag<Real>("1:") << aspect << " pair " << i << ": certified distance " << double(g.distance)
          << " vs whole set " << double(h.distance);
      evals_certified += c.iterations;
      evals_full += w.iterations;
      if (i % 6 < 4) {
        ++shallow;
        shallow_early += c.iterations < w.iterations;
      } else if (i % 6 == 4) {
        ++deep;
        deep_early += c.iterations < w.iterations;
      }
    }
    std::printf(
        "[ellipsoid] %s certificate 1:%-5g stopped early: shallow %d of %d, 0.8ρ deep %d of %d; evaluations "
        "%ld vs %ld\n",
        tag<Real>("").c_str(), aspect, shallow_early, shallow, deep_early, deep, evals_certified, evals_full);
    EXPECT_GE(shallow_early, shallow * 9 / 10)
        << "the certificate should stop shallow contacts after one start";
    EXPECT_GE(deep_early, deep * 8 / 10) << "the certificate should stop overlaps 0.8ρ deep after one start";
  }
}

// The lemma under the certificate, checked in long double without the engine: for an ellipsoid with
// semi-axes e (smallest e_min) and a boundary point x with outward normal u, the ball of radius
// e_min²/h(u) tangent inside at x lies inside the ellipsoid (h(u) = |D u|, x = D²u/h(u)); and it is
// the largest such ball at the tips (a ball 0.1 % larger pokes out next to the end of the longest axis),
// so the certificate's reach cannot be stretched.
TEST(EllipsoidCertificate, InscribedBallLemma) {
  std::mt19937_64 rng(4242);
  std::uniform_real_distribution<double> unit01(0, 1);
  LD worst = -1;
  int balls = 0;
  for (double aspect : {1.0, 1.5, 4.0, 10.0, 100.0}) {
    for (int k = 0; k < 200; ++k) {
      const Vec3<double> lo = random_axes<double>(rng, aspect);
      const LD e[3] = {LD(lo.x), LD(lo.y), LD(lo.z)};
      const LD emin = std::min({e[0], e[1], e[2]});
      const Vec3<double> ud = random_unit(rng);
      const LD u[3] = {LD(ud.x), LD(ud.y), LD(ud.z)};
      const LD h =
          std::sqrt(e[0] * e[0] * u[0] * u[0] + e[1] * e[1] * u[1] * u[1] + e[2] * e[2] * u[2] * u[2]);
      const LD radius = emin * emin / h;
      LD c[3];
      for (int i = 0; i < 3; ++i) c[i] = e[i] * e[i] * u[i] / h - radius * u[i];
      // Ball points: random directions, and directions close to the tangent point (where it is tight).
      for (int j = 0; j < 400; ++j) {
        Vec3<double> w = random_unit(rng);
        if (j % 2 == 1) {
          const double s = std::pow(10.0, -4.0 * unit01(rng));
          w = {ud.x + s * w.x, ud.y + s * w.y, ud.z + s * w.z};
          const double l = std::sqrt(w.x * w.x + w.y * w.y + w.z * w.z);
          w = {w.x / l, w.y / l, w.z / l};
        }
        const LD y[3] = {c[0] + radius * LD(w.x), c[1] + radius * LD(w.y), c[2] + radius * LD(w.z)};
        const LD q = y[0] * y[0] / (e[0] * e[0]) + y[1] * y[1] / (e[1] * e[1]) + y[2] * y[2] / (e[2] * e[2]);
        worst = std::max(worst, q - 1);
      }
      ++balls;
      if (aspect > 1) {  // the tip of the longest axis: a 0.1 % larger tangent ball leaves the body
        const int imax = int(std::max_element(e, e + 3) - e), imin = int(std::min_element(e, e + 3) - e);
        const LD big = LD(1.001) * emin * emin / e[imax];
        LD out = -1;
        for (int j = 1; j <= 200; ++j) {
          const LD phi = LD(j) * LD(1e-3);
          LD y[3] = {0, 0, 0};
          y[imax] = e[imax] - big + big * std::cos(phi);
          y[imin] = big * std::sin(phi);
          out = std::max(
              out, y[imax] * y[imax] / (e[imax] * e[imax]) + y[imin] * y[imin] / (e[imin] * e[imin]) - 1);
        }
        EXPECT_GT(out, LD(0)) << "aspect " << aspect
                              << ": a ball 0.1 % larger than e_min²/e_max at the tip fits";
      }
    }
  }
  std::printf("[ellipsoid] inscribed-ball lemma: %d balls, max (yᵀD⁻²y − 1) on their surfaces %.2Le\n", balls,
              worst);
  EXPECT_LE(worst, LD(1e-14)) << "a point of an inscribed ball lies outside the ellipsoid";
}

// The eigenvalue bound of the inner-ellipsoid certificate (ellipsoid_certificate.hpp): below the
// smallest eigenvalue always (it is what makes the certificate a proof), and close to it, also for
// repeated and clustered spectra (where Newton converges only linearly) and ill-conditioned ones.
TYPED_TEST(EllipsoidContactTest, SmallestEigenvalueBoundIsBelowAndClose) {
  using Real = TypeParam;
  std::mt19937_64 rng(515);
  std::uniform_real_distribution<double> u(0, 1);
  double worst_ratio = 1;
  int zero = 0;
  for (int i = 0; i < 3000; ++i) {
    double l[3] = {0.01 + u(rng), 0.01 + u(rng), 0.01 + u(rng)};
    if (i % 4 == 1) l[1] = l[0];                           // a double root
    if (i % 4 == 2) l[1] = l[2] = l[0];                    // a triple root
    if (i % 4 == 3) l[1] = l[0] * (1 + 1e-6), l[2] = 1e3;  // clustered, condition 1e5
    const Quat<double> q = random_quat<double>(rng);
    const Mat3<double> rm = rotation_matrix(q);
    auto entry = [&](int r, int c) {
      LD v = 0;
      for (int k = 0; k < 3; ++k) {
        const Vec3<double> col = column(rm, k);
        const double cr[3] = {col.x, col.y, col.z};
        v += LD(l[k]) * LD(cr[r]) * LD(cr[c]);
      }
      return Real(v);
    };
    const detail::Sym3<Real> g{entry(0, 0), entry(1, 1), entry(2, 2), entry(0, 1), entry(0, 2), entry(1, 2)};
    const double lmin = std::min({l[0], l[1], l[2]});
    const double bound = double(detail::smallest_eigenvalue_below(g));
    // The matrix was rounded to Real: its true smallest eigenvalue moved by at most ~3 ulps of the largest.
    const double moved = 8 * std::numeric_limits<Real>::epsilon() * std::max({l[0], l[1], l[2]});
    EXPECT_LE(bound, lmin + moved) << tag<Real>("") << " matrix " << i;
    if (i % 4 == 3) continue;  // condition 1e5: below is all that is asked (fp32 cannot resolve it)
    if (bound == 0) {
      ++zero;
      continue;
    }
    worst_ratio = std::min(worst_ratio, bound / lmin);
  }
  std::printf(
      "[ellipsoid] %s eigenvalue bound (spectra in [0.01, 1.01], simple to triple roots): worst "
      "bound/λmin %.4f, %d of 2250 refused\n",
      tag<Real>("").c_str(), worst_ratio, zero);
  EXPECT_GE(worst_ratio, 0.9) << "the bound should be close to the smallest eigenvalue";
  // (measured: fp64 0, fp32 28 — near-repeated roots, where fp32's Cholesky meets its rounding)
  EXPECT_LE(zero, 56) << "the Cholesky check should rarely refuse";
}

// The inner-ellipsoid certificate settles deep overlaps beyond the two balls' reach (a centre well
// inside the other body): each pair it certifies must be the global minimum by the exact reference,
// and must stop after the first start; pairs it refuses run the whole set. The count is printed.
TYPED_TEST(EllipsoidContactTest, InnerEllipsoidCertifiesDeepOverlapsExactly) {
  using Real = TypeParam;
  SolverSettings<Real> first_only;
  first_only.certify = false;
  first_only.starts = 1;
  first_only.screen = 0;
  for (double aspect : {2.0, 4.0, 10.0}) {
    Stats st;
    st.name = tag<Real>("inner ellipsoid 1:" + std::to_string(int(aspect)));
    std::mt19937_64 rng(9100 + int(aspect));
    std::uniform_real_distribution<double> u(-0.8, 0.8);
    int beyond_balls = 0, certified = 0;
    SolverSettings<Real> whole;
    whole.certify = false;
    for (int i = 0; i < 160; ++i) {
      Body<Real> a{{}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
      Body<Real> b{
          {Real(u(rng)), Real(u(rng)), Real(u(rng))}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
      const Ellipsoid<Real> ea = engine_body(a), eb = engine_body(b);
      const PerramWertheim<Real> pw = perram_wertheim(ea, eb);
      const EllipsoidContact<Real> c = ellipsoid_pair_contact(ea, eb, pw);  // the engine's solve
      const EllipsoidContact<Real> w = ellipsoid_pair_contact(ea, eb, pw, whole);
      const Real t = -c.geometry.distance;
      const Vec3<Real> n = c.geometry.normal_on_b;
      if (!c.converged || t < Real(0) || t <= detail::inscribed_ball_reach(ea, eb, n)) continue;
      ++beyond_balls;
      const Real noise = Real(16) * std::numeric_limits<Real>::epsilon() * Real(4);
      if (!detail::inner_ellipsoid_certificate(ea, eb, n, t, noise)) continue;
      ++certified;
      EXPECT_TRUE(c.geometry.distance == w.geometry.distance && n.x == w.geometry.normal_on_b.x &&
                  n.y == w.geometry.normal_on_b.y && n.z == w.geometry.normal_on_b.z)
          << st.name << " pair " << i << ": the whole start set finds another minimum";
      EXPECT_LT(c.iterations, w.iterations)
          << st.name << " pair " << i << ": the certificate should stop the solve";
      check_against_reference(a, b, c, st);
    }
    st.print();
    std::printf("[ellipsoid] %-28s beyond the two balls %d, certified by the inner ellipsoid %d\n",
                st.name.c_str(), beyond_balls, certified);
    EXPECT_GE(certified, beyond_balls / 2) << st.name << ": the inner ellipsoid should settle most of them";
    EXPECT_GE(beyond_balls, 20) << st.name << ": the sample should reach beyond the balls";
  }
}

}  // namespace
}  // namespace cg::test
