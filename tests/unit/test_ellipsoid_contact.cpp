// Ellipsoid and sphere–ellipsoid contacts (kernels/core/ellipsoid_contact.hpp, issue #12) against the
// exact long-double reference of src/reference/ellipsoid_reference.hpp, which shares no code with it.
//
// Tolerances are relative to the pair's scale s = (largest semi-axis of A) + (largest of B); the Tol
// struct lists them with the measured maxima (every suite prints its own: lines starting [ellipsoid]):
//   - distance: the engine evaluates f as a sum of norms (no cancellation beyond the final subtraction)
//     at a point whose tangential gradient is ≤ tol·s, so its error is O(eps·s) plus O(tol²·s/curvature):
//     fp32 1e-6·s (≈ 8 ulps), fp64 1e-12·s;
//   - positions and normal: a support point moves with n at the rate of the body's radius of curvature,
//     which for an axis ratio κ reaches κ × the largest semi-axis, so the allowance is scaled by the
//     larger axis ratio κ of the pair: positions fp32 4e-4·κ·s, fp64 2e-10·κ·s; normals fp32 5e-4·κ rad,
//     fp64 1e-9·κ rad;
//   - the identity position_on_a = position_on_b + n·distance holds to the solver tolerance: 2·tol·s
//     (plus the rounding of the coordinates themselves far from the origin);
//   - points on the surfaces: |D⁻¹ local_point| = 1 to a few ulps;
//   - decision: where the reference |distance| exceeds the distance band, the engine's decision
//     (distance ≤ 0) must agree with the reference; the independent long-double Perram–Wertheim sign
//     must agree with the reference minimum everywhere outside 1e-9 of F = 1.
// Pairs whose two best local minima are within the distance tolerance of each other (two equally deep
// exits) are "ambiguous": the distance must agree, the direction may be either; they are counted.
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
#include "reference/ellipsoid_reference.hpp"

namespace cg::test {
namespace {

using exact::LD;
constexpr double kPi = 3.14159265358979323846;

template <class Real>
struct Body {
  Vec3<Real> centre, axes;
  Quat<Real> q;
};

template <class Real>
Ellipsoid<Real> engine_body(const Body<Real>& b) {
  return make_ellipsoid(b.centre, b.axes, b.q);
}
template <class Real>
exact::Body reference_body(const Body<Real>& b) {
  return exact::make_body({LD(b.centre.x), LD(b.centre.y), LD(b.centre.z)},
                          {LD(b.axes.x), LD(b.axes.y), LD(b.axes.z)},
                          {LD(b.q.w), LD(b.q.x), LD(b.q.y), LD(b.q.z)});
}
template <class Real>
exact::Pair reference_pair(const Body<Real>& a, const Body<Real>& b) {
  exact::Pair p{reference_body(a), reference_body(b), {}};
  p.r = exact::sub(p.a.centre, p.b.centre);
  return p;
}

template <class Real>
Real scale_of(const Body<Real>& a, const Body<Real>& b) {
  auto mx = [](Vec3<Real> e) { return std::max(e.x, std::max(e.y, e.z)); };
  return mx(a.axes) + mx(b.axes);
}
template <class Real>
double aspect_of(const Body<Real>& x) {
  const Vec3<Real> e = x.axes;
  return double(std::max(e.x, std::max(e.y, e.z))) / double(std::min(e.x, std::min(e.y, e.z)));
}

template <class Real>
Quat<Real> random_quat(std::mt19937_64& rng) {
  std::normal_distribution<double> g;
  double w = g(rng), x = g(rng), y = g(rng), z = g(rng), n = std::sqrt(w * w + x * x + y * y + z * z);
  return {Real(w / n), Real(x / n), Real(y / n), Real(z / n)};
}
template <class Real>
Vec3<Real> random_axes(std::mt19937_64& rng, double aspect) {
  std::uniform_real_distribution<double> u(1.0 / aspect, 1.0);
  Vec3<Real> e{Real(u(rng)), Real(u(rng)), Real(u(rng))};
  // make the requested ratio reached: one axis 1, one 1/aspect (in random slots)
  std::uniform_int_distribution<int> slot(0, 2);
  int i = slot(rng), j = (i + 1 + slot(rng) % 2) % 3;
  Real* c[3] = {&e.x, &e.y, &e.z};
  *c[i] = Real(1);
  *c[j] = Real(1.0 / aspect);
  return e;
}
Vec3<double> random_unit(std::mt19937_64& rng) {
  std::normal_distribution<double> g;
  double x = g(rng), y = g(rng), z = g(rng), n = std::sqrt(x * x + y * y + z * z);
  return {x / n, y / n, z / n};
}

PackedShape<double> packed_double(const Body<double>& x) {
  const double semi[3] = {x.axes.x, x.axes.y, x.axes.z}, q[4] = {x.q.w, x.q.x, x.q.y, x.q.z};
  return pack_shape<double>(static_cast<std::uint8_t>(Shape::ellipsoid), semi, q);
}

// Per-suite statistics, printed and recorded.
struct Stats {
  std::string name;
  int pairs = 0, contacts = 0, nonconverged = 0, fallbacks = 0, ambiguous = 0, multi_minima = 0;
  long evaluations = 0;
  int max_evaluations = 0;
  double max_dist_err = 0, max_pos_err = 0, max_pos_err_kappa = 0, max_angle_deg = 0, max_identity = 0,
         max_surface = 0;
  void print() const {
    char line[512];
    std::snprintf(
        line, sizeof line,
        "[ellipsoid] %-28s pairs %5d contacts %5d | evals mean %.1f max %d | non-converged %d "
        "fallback %d | multi-minima %d ambiguous %d | max |Δd|/s %.2e  |Δp|/s %.2e  |Δp|/(κs) %.2e  "
        "angle %.2e°  identity/s %.2e  surface %.2e",
        name.c_str(), pairs, contacts, pairs ? double(evaluations) / pairs : 0.0, max_evaluations,
        nonconverged, fallbacks, multi_minima, ambiguous, max_dist_err, max_pos_err, max_pos_err_kappa,
        max_angle_deg, max_identity, max_surface);
    std::printf("%s\n", line);
    ::testing::Test::RecordProperty(name + "_evals_mean",
                                    std::to_string(pairs ? double(evaluations) / pairs : 0.0));
    ::testing::Test::RecordProperty(name + "_evals_max", max_evaluations);
    ::testing::Test::RecordProperty(name + "_nonconverged", nonconverged);
    ::testing::Test::RecordProperty(name + "_max_pos_err_rel", std::to_string(max_pos_err));
  }
};

template <class Real>
struct Tol {
  static constexpr bool fp32 = std::is_same_v<Real, float>;
  static constexpr double dist = fp32 ? 1e-6 : 1e-12;      // × s   (measured max: 1.9e-7, 4.1e-16)
  static constexpr double pos = fp32 ? 4e-4 : 2e-10;       // × κ s (measured max: 5.9e-5, 1.3e-11)
  static constexpr double angle_rad = fp32 ? 5e-4 : 1e-9;  // × κ   (measured max: 5.8e-5, 1.5e-10)
  static constexpr double identity = fp32 ? 4e-5 : 2e-11;  // × s   (2 × solver tolerance)
  static constexpr double surface = fp32 ? 1e-6 : 4e-15;   // |D⁻¹ local| − 1 (measured 2.8e-7, 6.7e-16)
};

double angle_between(Vec3<double> u, exact::V v) {
  const Vec3<double> w{double(v.x), double(v.y), double(v.z)};
  const Vec3<double> c = cross(u, w);
  return std::atan2(std::sqrt(dot(c, c)), dot(u, w));
}

template <class Real>
double dist3(Vec3<Real> p, exact::V q) {
  const double dx = double(p.x) - double(q.x), dy = double(p.y) - double(q.y), dz = double(p.z) - double(q.z);
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

// The identity and points-on-surface checks that need no reference.
template <class Real>
void check_self_consistency(const Body<Real>& a, const Body<Real>& b, const EllipsoidContact<Real>& c,
                            Stats& st) {
  const double s = double(scale_of(a, b));
  const auto& g = c.geometry;
  const double ix =
      double(g.position_on_a.x) - double(g.position_on_b.x) - double(g.normal_on_b.x) * double(g.distance);
  const double iy =
      double(g.position_on_a.y) - double(g.position_on_b.y) - double(g.normal_on_b.y) * double(g.distance);
  const double iz =
      double(g.position_on_a.z) - double(g.position_on_b.z) - double(g.normal_on_b.z) * double(g.distance);
  const double id = std::sqrt(ix * ix + iy * iy + iz * iz) / s;
  st.max_identity = std::max(st.max_identity, id);
  // plus the rounding of the world coordinates themselves (the pair may sit 1e6 from the origin)
  const double far = std::sqrt(double(dot(a.centre, a.centre))) + std::sqrt(double(dot(b.centre, b.centre)));
  EXPECT_LE(id, Tol<Real>::identity + 8 * std::numeric_limits<Real>::epsilon() * far / s)
      << st.name << ": position_on_a ≠ position_on_b + n·distance";
  const double nn = double(dot(g.normal_on_b, g.normal_on_b));
  EXPECT_NEAR(nn, 1.0, 8 * std::numeric_limits<Real>::epsilon());
  auto on_surface = [](Vec3<Real> local, Vec3<Real> e) {
    const double x = double(local.x) / e.x, y = double(local.y) / e.y, z = double(local.z) / e.z;
    return std::abs(std::sqrt(x * x + y * y + z * z) - 1.0);
  };
  const double sa = on_surface(c.local_point_a, a.axes), sb = on_surface(c.local_point_b, b.axes);
  st.max_surface = std::max({st.max_surface, sa, sb});
  EXPECT_LE(sa, Tol<Real>::surface) << st.name;
  EXPECT_LE(sb, Tol<Real>::surface) << st.name;
  // local points are R_Xᵀ(p − x): back in the world they give the positions
  const Ellipsoid<Real> ea = engine_body(a);
  const Vec3<Real> back = ea.centre + mul(ea.rotation, c.local_point_a);
  EXPECT_LE(std::sqrt(double(dot(back - g.position_on_a, back - g.position_on_a))),
            16 * s * std::numeric_limits<Real>::epsilon());
}

// Compares one pair with the reference; `c` is the engine's answer for (a, b).
template <class Real>
void check_against_reference(const Body<Real>& a, const Body<Real>& b, const EllipsoidContact<Real>& c,
                             Stats& st, int samples = 8000) {
  const exact::Pair p = reference_pair(a, b);
  const exact::Reference ref = exact::exact_contact(p, samples);
  const double s = double(scale_of(a, b));
  const double kappa = std::max(aspect_of(a), aspect_of(b));
  const auto& g = c.geometry;
  ++st.pairs;
  st.evaluations += c.iterations;
  st.max_evaluations = std::max(st.max_evaluations, c.iterations);
  st.nonconverged += !c.converged;
  st.fallbacks += c.fallback;
  st.multi_minima += ref.minima > 1 && std::isfinite(double(ref.second_gap));
  EXPECT_TRUE(c.converged) << st.name;
  const double derr = std::abs(double(g.distance) - double(ref.distance)) / s;
  st.max_dist_err = std::max(st.max_dist_err, derr);
  EXPECT_LE(derr, Tol<Real>::dist) << st.name << ": distance " << g.distance << " reference "
                                   << double(ref.distance);
  // decision
  const double band = Tol<Real>::dist * s;
  if (double(ref.distance) < -band) {
    EXPECT_LE(g.distance, Real(0)) << st.name;
  }
  if (double(ref.distance) > band) {
    EXPECT_GT(g.distance, Real(0)) << st.name;
  }
  st.contacts += ref.distance <= 0;
  const double angle =
      angle_between({double(g.normal_on_b.x), double(g.normal_on_b.y), double(g.normal_on_b.z)}, ref.n);
  const bool ambiguous = double(ref.second_gap) <= 4 * band;
  if (ambiguous && angle > Tol<Real>::angle_rad * kappa) {
    ++st.ambiguous;  // an equally deep other exit: the distance agreed, the direction may differ
  } else {
    const double pe =
        std::max(dist3(g.position_on_a, ref.position_on_a), dist3(g.position_on_b, ref.position_on_b)) / s;
    st.max_pos_err = std::max(st.max_pos_err, pe);
    st.max_pos_err_kappa = std::max(st.max_pos_err_kappa, pe / kappa);
    st.max_angle_deg = std::max(st.max_angle_deg, angle * 180 / kPi);
    EXPECT_LE(pe, Tol<Real>::pos * kappa) << st.name << ": position error";
    EXPECT_LE(angle, Tol<Real>::angle_rad * kappa) << st.name << ": normal angle";
  }
  check_self_consistency(a, b, c, st);
}

template <class Real>
EllipsoidContact<Real> solve(const Body<Real>& a, const Body<Real>& b) {
  const Ellipsoid<Real> ea = engine_body(a), eb = engine_body(b);
  return ellipsoid_pair_contact(ea, eb, perram_wertheim(ea, eb));
}

template <class T>
class EllipsoidContactTest : public ::testing::Test {};
using Reals = ::testing::Types<float, double>;
TYPED_TEST_SUITE(EllipsoidContactTest, Reals);

template <class Real>
std::string tag(const std::string& what) {
  return (std::is_same_v<Real, float> ? "fp32 " : "fp64 ") + what;
}

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

// A pair touching by construction: B at a fixed place, A's support point at −n on B's at n (long
// double), for a random unit n; `off` = ∇h_A(n) + ∇h_B(n), so a = b + off touches with normal n.
template <class Real>
struct TouchingPair {
  Body<Real> a, b;
  exact::V n, off;
};
template <class Real>
TouchingPair<Real> touching_pair(std::mt19937_64& rng, double aspect) {
  Body<Real> b{{Real(0.25), Real(0.5), Real(-0.125)}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
  Body<Real> a{{}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
  const Vec3<double> nd = random_unit(rng);
  const exact::V n{nd.x, nd.y, nd.z};
  const exact::V off =
      exact::add(exact::support_point(reference_body(a), n), exact::support_point(reference_body(b), n));
  return {a, b, n, off};
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

// Regression: deep-overlap pairs from stress runs against the reference (25 500 pairs) that the 8 fixed
// starts alone missed: the first three because every start's local minimum had n·(a − b) slightly < 0
// (the reflection step, f(−n) = f(n) + 2 n·(a − b), finds them), the last three because the global
// minimum was the other member of a near-antipodal pair (the antipode run of the best finds them), the
// last two because only a start on a bisector of the two thinnest axes reaches the global basin.
TYPED_TEST(EllipsoidContactTest, StressRegressionsFindTheGlobalMinimum) {
  using Real = TypeParam;
  struct Case {
    double ca[3], ea[3], qa[4], eb[3], qb[4];
  };
  const Case cases[] = {
      {{0.049542257354311621, 0.14817446361617703, 0.13524127485246873},
       {0.39890412320856294, 0.1, 1},
       {0.61743728553071586, 0.090915736755512955, 0.11927972182337954, -0.77219031022695495},
       {0.1, 1, 0.94841511613814156},
       {0.63802047908912074, 0.48402020116488426, 0.59883563543024076, 0.0070848335233370677}},
      {{0.000484219599129046, 0.043074411189862709, -0.038518702578834656},
       {0.35479756170210119, 1, 0.033333333333333333},
       {-0.18465566757782412, -0.53103708767443802, 0.20446890012396995, -0.80130790887631542},
       {0.033333333333333333, 1, 0.82841134966793206},
       {-0.11978901692020688, -0.87953959017022787, -0.26293513889727227, -0.3780553047922357}},
      {{-0.0065130036549601944, 0.0038105383137064957, -0.0095967166369569715},
       {1, 0.033333333333333333, 0.74944884971445258},
       {0.063627517368558956, 0.68436826300371889, 0.58700521570917941, 0.42780427342069188},
       {1, 0.033333333333333333, 0.99070098532038287},
       {-0.05646489502143727, 0.65540444996466629, 0.39037977588006711, -0.64409654026439223}},
      // the antipode of the best (both minima of a near-antipodal pair have n·(a − b) ≥ 0)
      {{-0.084109126343144436, -0.058795716452977355, 0.066277818092687513},
       {0.1, 0.78659757859572332, 1},
       {0.13126628149967398, 0.18293575005248197, -0.84460755576860769, 0.48573835697066636},
       {1, 0.15171741778757208, 0.1},
       {-0.19366645094002125, 0.33414988573635879, -0.18373323124907187, 0.90392436596069792}},
      {{-0.071793084780539473, -0.032942741979032873, 0.085427981531328342},
       {0.01, 1, 0.73627998821418961},
       {-0.17444306193123776, 0.50071558519065729, -0.22773204020460522, -0.81669556063167137},
       {0.49742891350542395, 1, 0.01},
       {-0.46034748719661761, 0.61151979069887819, 0.61981178524950487, -0.17308115865449328}},
      {{-0.10492550741794275, 0.41262328293926287, 0.097118498565802638},
       {1, 0.36154376727745097, 0.01},
       {-0.75519479931300515, -0.24227898027168746, -0.34310920299637504, 0.50324724105383178},
       {1, 0.044398813756797779, 0.01},
       {-0.44177014942373927, 0.43186847900398134, 0.65359029793764367, -0.43720530001670493}},
      // a basin reached only from a bisector of the two thinnest axes
      {{-0.037560377134184059, 0.0082757546250927464, -0.067666803393867797},
       {0.58275192939414588, 1, 0.033333333333333333},
       {-0.80319333560130446, 0.38242762229910854, 0.018271127324890876, -0.45639428705295876},
       {1, 0.033333333333333333, 0.6866074387140858},
       {-0.27217029700598439, 0.78872783206935249, 0.1106557007252128, 0.53998801120382811}},
      {{-0.16424703621346728, -0.10398868594066041, -0.053995465732879118},
       {0.033333333333333333, 1, 0.89207983420609527},
       {-0.4512197183440379, -0.51653229081008389, -0.72679728461896631, -0.036889909169193526},
       {1, 0.033333333333333333, 0.94147190868366704},
       {-0.70679441763114437, 0.2642834297095179, -0.65111284570600969, -0.081535158938016772}},
  };
  Stats st;
  st.name = tag<Real>("stress regressions");
  for (const Case& c : cases) {
    const Body<Real> a{{Real(c.ca[0]), Real(c.ca[1]), Real(c.ca[2])},
                       {Real(c.ea[0]), Real(c.ea[1]), Real(c.ea[2])},
                       {Real(c.qa[0]), Real(c.qa[1]), Real(c.qa[2]), Real(c.qa[3])}};
    const Body<Real> b{{0, 0, 0},
                       {Real(c.eb[0]), Real(c.eb[1]), Real(c.eb[2])},
                       {Real(c.qb[0]), Real(c.qb[1]), Real(c.qb[2]), Real(c.qb[3])}};
    check_against_reference(a, b, solve(a, b), st, 20000);
  }
  st.print();
}

// The start set's runs are functions of their starts alone (ellipsoid_solve.hpp: newton_run), so a
// provider that runs every start of a batch before taking any — what the device's warp kernel does,
// one start per lane (cuda/narrow.cuh: WarpRuns) — gives SerialRuns' bits and counts. Checked here on
// the host with such a provider, over pairs that run the whole set: deep and crossed overlaps at
// aspects 2–20, the certificates on and off, and a starved cap (the safety net's batch).
struct BatchFirstRuns {
  mutable int unused = 0;  // runs made that the solve did not take
  template <class Start, class Run, class More, class Take>
  void batch(int count, const Start& start, const Run& run, const More& more, const Take& take) const {
    using Result = decltype(run(start(0)));
    std::vector<Result> res(static_cast<std::size_t>(count));
    std::vector<bool> valid(static_cast<std::size_t>(count));
    for (int j = 0; j < count; ++j) {
      const auto s = start(j);
      valid[j] = !is_zero(s);
      if (valid[j]) res[j] = run(s);
    }
    int j = 0;
    for (; j < count && more(); ++j)
      if (valid[j]) take(res[j]);
    for (; j < count; ++j) unused += valid[j] ? 1 : 0;
  }
};

TYPED_TEST(EllipsoidContactTest, RunsTakenInBatchesGiveTheSerialBits) {
  using Real = TypeParam;
  std::mt19937_64 rng(12000);
  std::uniform_real_distribution<double> u(-0.9, 0.9);
  SolverSettings<Real> certify, whole, starved;
  whole.certify = false;
  starved.max_iterations = 2;
  int pairs = 0, fallbacks = 0, unused = 0;
  for (double aspect : {2.0, 5.0, 20.0})
    for (int i = 0; i < 60; ++i) {
      Body<Real> a{{}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
      Body<Real> b{
          {Real(u(rng)), Real(u(rng)), Real(u(rng))}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
      const Ellipsoid<Real> ea = engine_body(a), eb = engine_body(b);
      const PerramWertheim<Real> pw = perram_wertheim(ea, eb);
      for (const SolverSettings<Real>* st : {&certify, &whole, &starved}) {
        const EllipsoidContact<Real> s = ellipsoid_pair_contact(ea, eb, pw, *st);
        const BatchFirstRuns batched;
        const EllipsoidContact<Real> w = ellipsoid_pair_contact(ea, eb, pw, *st, batched);
        const std::string what = "aspect " + std::to_string(aspect) + " pair " + std::to_string(i);
        EXPECT_EQ(s.geometry.distance, w.geometry.distance) << what;
        EXPECT_EQ(s.geometry.normal_on_b.x, w.geometry.normal_on_b.x) << what;
        EXPECT_EQ(s.geometry.normal_on_b.y, w.geometry.normal_on_b.y) << what;
        EXPECT_EQ(s.geometry.normal_on_b.z, w.geometry.normal_on_b.z) << what;
        EXPECT_EQ(s.iterations, w.iterations) << what;
        EXPECT_EQ(s.converged, w.converged) << what;
        EXPECT_EQ(s.fallback, w.fallback) << what;
        ++pairs;
        fallbacks += s.fallback;
        unused += batched.unused;
      }
    }
  std::printf("[ellipsoid] %-28s %d solves, %d runs made and not taken, %d fallbacks\n",
              tag<Real>("runs in batches").c_str(), pairs, unused, fallbacks);
  EXPECT_GT(unused, 0) << "some batch should stop at a certified minimum";
  EXPECT_GT(fallbacks, 0) << "the starved cap should reach the safety net's batch";
}

// Never silently wrong about convergence: with an iteration cap too small to converge (1 evaluation per
// start, 4 in the continuation), a pair reports converged = false with `fallback` set. (Converged then
// means a local minimum only: with starved starts it need not be the global one, and it is not checked.)
TYPED_TEST(EllipsoidContactTest, StarvedSolverIsFlagged) {
  using Real = TypeParam;
  std::mt19937_64 rng(10000);
  std::uniform_real_distribution<double> u(0, 0.8);
  SolverSettings<Real> starved;
  starved.max_iterations = 1;
  int flagged = 0, converged_anyway = 0;
  for (int i = 0; i < 40; ++i) {
    Body<Real> b{{}, random_axes<Real>(rng, 20), random_quat<Real>(rng)};
    Body<Real> a{{}, random_axes<Real>(rng, 20), random_quat<Real>(rng)};
    const Vec3<double> d = random_unit(rng);
    const double len = u(rng) * double(scale_of(a, b));
    a.centre = {Real(len * d.x), Real(len * d.y), Real(len * d.z)};
    const Ellipsoid<Real> ea = engine_body(a), eb = engine_body(b);
    const EllipsoidContact<Real> c = ellipsoid_pair_contact(ea, eb, perram_wertheim(ea, eb), starved);
    if (!c.converged) {
      ++flagged;
      EXPECT_TRUE(c.fallback);
      continue;
    }
    ++converged_anyway;
    EXPECT_TRUE(c.fallback);  // every start stopped unconverged, so the safety net ran
  }
  std::printf(
      "[ellipsoid] %-28s max_iterations 1: %d flagged non-converged, %d converged by the continuation\n",
      tag<Real>("starved solver").c_str(), flagged, converged_anyway);
  EXPECT_GT(flagged, 0);
}

}  // namespace
}  // namespace cg::test
