#pragma once
// The ellipsoid contact tests' shared pieces (test_ellipsoid_contact.cpp: contacts against the reference,
// test_ellipsoid_certificates.cpp: the certificates of globality, test_ellipsoid_start_set.cpp: the start
// set and how its runs are taken): bodies and their exact long-double reference, random and touching
// pairs, the per-suite statistics, the tolerances and the checks against the reference, and the typed
// fixture (in a named namespace: its tests are in three files, and GoogleTest wants one fixture class
// per suite).
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

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <string>
#include <type_traits>

#include "core/contact.hpp"
#include "core/ellipsoid_contact.hpp"
#include "core/quat.hpp"
#include "core/shape_narrow.hpp"
#include "reference/ellipsoid_reference.hpp"

namespace cg::test {

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
inline Vec3<double> random_unit(std::mt19937_64& rng) {
  std::normal_distribution<double> g;
  double x = g(rng), y = g(rng), z = g(rng), n = std::sqrt(x * x + y * y + z * z);
  return {x / n, y / n, z / n};
}

inline PackedShape<double> packed_double(const Body<double>& x) {
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

inline double angle_between(Vec3<double> u, exact::V v) {
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

template <class Real>
std::string tag(const std::string& what) {
  return (std::is_same_v<Real, float> ? "fp32 " : "fp64 ") + what;
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

}  // namespace cg::test
