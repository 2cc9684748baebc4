#pragma once
// An ellipsoid as the narrow phase sees it, the solver settings and the result of a contact solve,
// and the small 3×3 helpers of the ellipsoid narrow phase (core/ellipsoid_contact.hpp: the overview).
#include <limits>
#include <type_traits>

#include "core/config.hpp"
#include "core/contact.hpp"
#include "core/quat.hpp"
#include "core/vec3.hpp"

namespace cg {

// An ellipsoid as the narrow phase sees it: the rotation is built once per body (make_ellipsoid).
template <class Real>
struct Ellipsoid {
  Vec3<Real> centre;
  Vec3<Real> semi_axes;  // along the body's x, y, z
  Mat3<Real> rotation;   // body → world
};

template <class Real>
CG_HD Ellipsoid<Real> make_ellipsoid(Vec3<Real> centre, Vec3<Real> semi_axes, Quat<Real> orientation) {
  return {centre, semi_axes, rotation_matrix(orientation)};
}

// Newton stops when the tangential gradient |P ∇f| ≤ tolerance · scale, scale = the largest semi-axis of
// A plus that of B. That gradient is exactly the defect of the identity position_on_a = position_on_b +
// n·d, so the tolerance bounds it relative to the body size. Defaults: fp32 2e-5 (≈ 170 ulps: the
// gradient's own rounding is ~10 ulps), fp64 1e-11; Newton converges quadratically, so the tolerance
// costs about one evaluation per start either way.
template <class Real>
struct SolverSettings {
  Real tolerance = std::is_same_v<Real, float> ? Real(2e-5) : Real(1e-11);
  int max_iterations = 40;  // per start (trial evaluations)
  int starts = 11;          // how many of the fixed ordered starts to use (1 … 11)
  int screen = 3;           // Newton runs from the lowest of 20 screened directions (0 … 4)
  // Stop as soon as a start's minimum is certified global (ellipsoid_solve.hpp: the inscribed-ball
  // certificate); false runs the whole start set (tests compare the two).
  bool certify = true;
};

template <class Real>
struct EllipsoidContact {
  ContactGeometry<Real> geometry;
  Vec3<Real> local_point_a, local_point_b;  // R_Xᵀ(position_on_x − x)
  Real pw;                                  // Perram–Wertheim F (−1 where not computed)
  int iterations;                           // evaluations of f, all starts together
  bool converged;                           // the winning minimiser meets the tolerance
  bool fallback;                            // the fixed start set did not suffice (extra starts ran)
  bool complete = true;  // false: a first-start-only solve stopped uncertified (SolveScope::first_start*)
};

// How much of the ellipsoid solve to run: all of it, or only the first start, stopping uncertified
// (`complete` false, no geometry) so that a later pass runs the rest for those pairs alone — the
// device's narrow stage, where one thread's full solve would idle the rest of its warp.
// first_start_cheap tries only the cheap certificates (separated, two inscribed balls): the triage
// pass over every candidate; first_start adds the inner-ellipsoid one (ellipsoid_certificate.hpp),
// which costs about five evaluations of f, over the few candidates triage leaves.
// none: no general solve at all (a pair of two general ellipsoids comes back incomplete) — for callers
// that rebuild those rows from a kept minimiser and need only the closed forms and root finds, without
// the solve's registers and stack (the device's fill kernel).
enum class SolveScope { whole, first_start, first_start_cheap, none };

namespace detail {

template <class Real>
CG_HD Real cg_abs(Real v) {
  return v < Real(0) ? -v : v;
}
template <class Real>
CG_HD Real cg_max(Real a, Real b) {
  return a < b ? b : a;
}
template <class Real>
CG_HD Real cg_min(Real a, Real b) {
  return b < a ? b : a;
}
template <class Real>
CG_HD Vec3<Real> hadamard(Vec3<Real> a, Vec3<Real> b) {
  return {a.x * b.x, a.y * b.y, a.z * b.z};
}
template <class Real>
CG_HD Real max_axis(Vec3<Real> e) {
  return cg_max(e.x, cg_max(e.y, e.z));
}
template <class Real>
CG_HD Real min_axis(Vec3<Real> e) {
  return cg_min(e.x, cg_min(e.y, e.z));
}
template <class Real>
CG_HD int min_index(Vec3<Real> e) {
  return e.x <= e.y ? (e.x <= e.z ? 0 : 2) : (e.y <= e.z ? 1 : 2);
}
template <class Real>
CG_HD int max_index(Vec3<Real> e) {
  return e.x >= e.y ? (e.x >= e.z ? 0 : 2) : (e.y >= e.z ? 1 : 2);
}
template <class Real>
CG_HD Vec3<Real> normalized(Vec3<Real> v) {
  return (Real(1) / cg_sqrt(dot(v, v))) * v;
}

// The support value h(n) = |D Rᵀ n| of an ellipsoid about its centre.
template <class Real>
CG_HD Real support_value(const Ellipsoid<Real>& e, Vec3<Real> n) {
  const Vec3<Real> w = hadamard(e.semi_axes, mul_transpose(e.rotation, n));
  return cg_sqrt(dot(w, w));
}

// Symmetric 3×3 matrix.
template <class Real>
struct Sym3 {
  Real xx, yy, zz, xy, xz, yz;
};

template <class Real>
CG_HD Vec3<Real> mul(const Sym3<Real>& m, Vec3<Real> v) {
  return {m.xx * v.x + m.xy * v.y + m.xz * v.z, m.xy * v.x + m.yy * v.y + m.yz * v.z,
          m.xz * v.x + m.yz * v.y + m.zz * v.z};
}

// R D² Rᵀ: the "covariance" form of the ellipsoid, whose support function is sqrt(uᵀ A u).
template <class Real>
CG_HD Sym3<Real> covariance(const Ellipsoid<Real>& e) {
  const Vec3<Real> d2 = hadamard(e.semi_axes, e.semi_axes);
  const Mat3<Real>& r = e.rotation;
  return {dot(hadamard(r.r0, d2), r.r0), dot(hadamard(r.r1, d2), r.r1), dot(hadamard(r.r2, d2), r.r2),
          dot(hadamard(r.r0, d2), r.r1), dot(hadamard(r.r0, d2), r.r2), dot(hadamard(r.r1, d2), r.r2)};
}

// The adjugate (cofactor matrix) and determinant: inverse = adj / det.
template <class Real>
CG_HD Sym3<Real> adjugate(const Sym3<Real>& m, Real& det) {
  Sym3<Real> c{m.yy * m.zz - m.yz * m.yz, m.xx * m.zz - m.xz * m.xz, m.xx * m.yy - m.xy * m.xy,
               m.xz * m.yz - m.xy * m.zz, m.xy * m.yz - m.xz * m.yy, m.xy * m.xz - m.xx * m.yz};
  det = m.xx * c.xx + m.xy * c.xy + m.xz * c.xz;
  return c;
}

}  // namespace detail

}  // namespace cg
