#pragma once
// Narrow phase for ellipsoid pairs and sphere–ellipsoid pairs (issue #12), shared by both backends.
//
// Semantics (CONTRACT §3, Bullet's convex–convex contacts). For a unit direction n (from B towards A)
//   f(n) = h_A(−n) + h_B(n) − n·(a − b),   h_X(u) = |D_X R_Xᵀ u|  (support function about the centre),
// distance = −min_{|n|=1} f, n = the GLOBAL minimiser, position_on_b = b + ∇h_B(n),
// position_on_a = a + ∇h_A(−n), so position_on_a = position_on_b + n·distance (at the minimiser; to the
// solver tolerance in practice). −min f is the signed distance from the origin to the boundary of the
// Minkowski difference A − B, i.e. minus the penetration depth when overlapping and the gap otherwise.
// Contact iff distance ≤ 0.
//
// Structure of the problem. h is even, so f(−n) − f(n) = 2 n·(a − b): the global minimiser has
// n·(a − b) ≥ 0, and every start is put on that side. f is convex and 1-homogeneous on ℝ³, so for a
// separated pair (min f < 0) the minimum over the unit ball is a convex problem; local minima that are not
// global appear only when the bodies overlap (elongated bodies, deep or crossed overlap). Hence:
//   1. perram_wertheim(): the exact overlap test F = max_λ λ(1−λ) rᵀ[(1−λ)A + λB]⁻¹ r, a 1-D concave
//      maximisation (safeguarded Newton), A = R_A D_A² R_Aᵀ. (Issue #12 writes A⁻¹ inside the bracket;
//      that is Perram–Wertheim's form for the *shape* matrix R D⁻² Rᵀ — with A = R D² Rᵀ the bracket holds
//      A itself, which gives F = |r|²/(ra + rb)² for spheres.) F < 1 overlap, F = 1 touching. It is
//      global (no local maxima), costs ~5 solves of a 3×3 system, rejects candidates cheaply, and its
//      maximiser gives the normal at which the homothetically scaled bodies touch: the first start.
//   2. ellipsoid_pair_contact(): damped Newton (Levenberg–Marquardt shift + trust radius) on the tangent
//      plane of the unit sphere, analytic gradient and Hessian, from a fixed ordered start set: the PW
//      normal, the centre direction, the three axes of A, the three axes of B, the two bisectors of the
//      thinnest axes of A and B, the common normal of their longest axes (each signed towards a − b);
//      then from the 3 lowest of a screen of 20 directions (cube and face diagonals of both body
//      frames, f values only). Two cheap global moves: a local minimum with n·(a − b) < 0 is reflected
//      (f(−n) = f(n) + 2 n·(a − b) is lower) and Newton continues from −n; and Newton runs once more
//      from the antipode of the best (when a − b is short, minima come in near-antipodal pairs). A start
//      whose iterate comes within 1e-4 rad of the converged best stops there (same minimum). The
//      smallest f wins; a later candidate must be lower by more than the rounding of f (ties keep the
//      earlier start). Each ingredient was added after a stress run against the exact reference
//      (deep overlaps — a centre inside the other body — and random overlaps, axis ratios 3–100, double)
//      showed misses; the unit tests keep those pairs: 8 axis starts missed 3 of 7 500 (all with
//      n·(a − b) < 0: reflection), then 3 of 18 000 (antipodal pairs: antipode run), then 2 of 24 000
//      (bisector starts), then 1 of 24 000 (screen); the final set missed none of 48 000 fresh pairs.
//      5 axis starts alone miss deep overlaps routinely (A's centre inside B needs B's axes).
//   3. Safety net, never silently wrong: if the best minimum disagrees with the PW sign beyond rounding
//      (a missed global minimum), or the winning start did not converge, 13 more fixed directions are
//      tried and a continuation runs from the best point with 4× the iteration cap; `fallback` is set,
//      and `converged` is false if even that does not meet the tolerance.
//   4. sphere_ellipsoid_contact(): the closest point of the ellipsoid to the sphere centre by a 1-D root
//      find on the normal equation x_i = e_i² p_i / (e_i² + t) (the largest root t > −e_min², which is
//      the global closest point inside and outside), the same semantics and outputs.
//   Equal semi-axes fall back to the closed form sphere_sphere_contact (bitwise identical).
//
// Coincident centres (a − b = 0 exactly): f is even and every minimiser comes in a pair ±n. (1, 0, 0)
// replaces the PW normal and the centre direction (neither exists) as the first start; the result is made
// canonical: the first non-zero component of n is positive — on every path (two spheres keep
// n = (1, 0, 0), which satisfies it; the sphere–ellipsoid path takes the ellipsoid's smallest axis).
//
// All functions: host and device, no allocation, no recursion, fixed iteration caps. Points are in the
// caller's frame (the engine's local frame: use centre differences, not 1e6-sized coordinates in fp32).
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
};

template <class Real>
struct EllipsoidContact {
  ContactGeometry<Real> geometry;
  Vec3<Real> local_point_a, local_point_b;  // R_Xᵀ(position_on_x − x)
  Real pw;                                  // Perram–Wertheim F (−1 where not computed)
  int iterations;                           // evaluations of f, all starts together
  bool converged;                           // the winning minimiser meets the tolerance
  bool fallback;                            // the fixed start set did not suffice (extra starts ran)
};

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

// ---------------------------------------------------------------------------------------------------
// Perram–Wertheim contact function.

template <class Real>
struct PerramWertheim {
  Real value;         // F(λ*) = max over λ ∈ [0, 1]; < 1 overlap, 1 touching, > 1 apart
  Real lambda;        // λ*
  Vec3<Real> normal;  // [(1−λ*)A + λ*B]⁻¹ r, normalised: the touching normal of the scaled bodies, B → A
  Real band;          // F's rounding band from the conditioning: |F − F_exact| ≲ band · F
  int iterations;
};

// Safeguarded Newton on F'(λ) = 0 over the bracket [0, 1] (F'(0) = rᵀA⁻¹r > 0, F'(1) = −rᵀB⁻¹r < 0; F
// is concave, so the root is unique). Each step solves with C = (1−λ)A + λB through its adjugate.
template <class Real>
CG_HD PerramWertheim<Real> perram_wertheim(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b) {
  using detail::Sym3;
  const Vec3<Real> r = a.centre - b.centre;
  const Sym3<Real> ma = detail::covariance(a), mb = detail::covariance(b);
  const Sym3<Real> k{mb.xx - ma.xx, mb.yy - ma.yy, mb.zz - ma.zz,
                     mb.xy - ma.xy, mb.xz - ma.xz, mb.yz - ma.yz};
  const Real eps = std::numeric_limits<Real>::epsilon();
  const Real cond_a = detail::max_axis(a.semi_axes) / detail::min_axis(a.semi_axes);
  const Real cond_b = detail::max_axis(b.semi_axes) / detail::min_axis(b.semi_axes);
  const Real cond = detail::cg_max(cond_a, cond_b);
  PerramWertheim<Real> out{Real(0), Real(0.5), {Real(1), Real(0), Real(0)}, Real(64) * eps * cond * cond, 0};
  if (r.x == Real(0) && r.y == Real(0) && r.z == Real(0)) return out;

  // A start from the sphere formula with the bounding radii projected on r: λ = ρa / (ρa + ρb).
  const Real rr = dot(r, r);
  const Real ra = cg_sqrt(dot(r, detail::mul(ma, r)) / rr), rb = cg_sqrt(dot(r, detail::mul(mb, r)) / rr);
  Real lo = Real(0), hi = Real(1), lam = ra / (ra + rb);
  Real best_f = Real(0);
  Vec3<Real> best_x = r;
  const int cap = 32;
  int it = 0;
  for (; it < cap; ++it) {
    const Sym3<Real> c{ma.xx + lam * k.xx, ma.yy + lam * k.yy, ma.zz + lam * k.zz,
                       ma.xy + lam * k.xy, ma.xz + lam * k.xz, ma.yz + lam * k.yz};
    Real det;
    const Sym3<Real> adj = detail::adjugate(c, det);
    const Real inv_det = Real(1) / det;
    const Vec3<Real> x = inv_det * detail::mul(adj, r);  // C⁻¹ r
    const Vec3<Real> y = detail::mul(k, x);              // K x
    const Vec3<Real> z = inv_det * detail::mul(adj, y);  // C⁻¹ K x
    const Real phi = dot(r, x), dphi = -dot(x, y), d2phi = Real(2) * dot(y, z);
    const Real w = lam * (Real(1) - lam);
    const Real fval = w * phi;
    if (fval > best_f || it == 0) {
      best_f = fval;
      best_x = x;
      out.lambda = lam;
    }
    const Real d1 = (Real(1) - Real(2) * lam) * phi + w * dphi;
    const Real d2 = Real(-2) * phi + Real(2) * (Real(1) - Real(2) * lam) * dphi + w * d2phi;
    // F is flat at λ*: an error δ in λ costs ½|F''|δ² in F, so a Newton step below √eps/10 ends it
    // (further steps would only chase the rounding of F').
    const Real newton = d2 < Real(0) ? -d1 / d2 : Real(0);
    if (d2 < Real(0) && detail::cg_abs(newton) <= Real(0.1) * cg_sqrt(eps)) {
      if (lam + newton >= lo && lam + newton <= hi) lam += newton;
      ++it;
      break;
    }
    if (d1 > Real(0)) {
      lo = lam;
    } else {
      hi = lam;
    }
    Real next = lam + newton;
    if (!(d2 < Real(0)) || !(next > lo && next < hi)) next = Real(0.5) * (lo + hi);
    lam = next;
    if (hi - lo <= Real(4) * eps) {
      ++it;
      break;
    }
  }
  // One last evaluation at the final λ (the loop keeps the best value seen).
  {
    const Sym3<Real> c{ma.xx + lam * k.xx, ma.yy + lam * k.yy, ma.zz + lam * k.zz,
                       ma.xy + lam * k.xy, ma.xz + lam * k.xz, ma.yz + lam * k.yz};
    Real det;
    const Sym3<Real> adj = detail::adjugate(c, det);
    const Vec3<Real> x = (Real(1) / det) * detail::mul(adj, r);
    const Real fval = lam * (Real(1) - lam) * dot(r, x);
    if (fval > best_f) {
      best_f = fval;
      best_x = x;
      out.lambda = lam;
    }
  }
  out.value = best_f;
  out.normal = detail::normalized(best_x);
  out.iterations = it + 1;
  return out;
}

// The cheap filter: false only where the pair is certainly apart (F beyond its rounding band).
template <class Real>
CG_HD bool pw_may_touch(const PerramWertheim<Real>& pw) {
  return pw.value <= Real(1) + pw.band;
}

// ---------------------------------------------------------------------------------------------------
// The contact solve.

namespace detail {

// f, its tangential gradient and its Riemannian Hessian at n, in the tangent basis (t1, t2).
template <class Real>
struct Evaluation {
  Vec3<Real> n, t1, t2;
  Real f, g1, g2, h11, h12, h22;
};

// Adds h(n), ∇h·t_i and t_iᵀ ∇²h t_j of one ellipsoid: with v = Rᵀn, w = D v, h = |w|,
// ∇h = R D² v / h and ∇²h = R (D² − D²v vᵀD² / h²) Rᵀ / h.
template <class Real>
CG_HD void add_body(const Ellipsoid<Real>& e, Evaluation<Real>& ev) {
  const Vec3<Real> d = e.semi_axes;
  const Vec3<Real> w = hadamard(d, mul_transpose(e.rotation, ev.n));
  const Vec3<Real> u1 = hadamard(d, mul_transpose(e.rotation, ev.t1));
  const Vec3<Real> u2 = hadamard(d, mul_transpose(e.rotation, ev.t2));
  const Real h = cg_sqrt(dot(w, w)), inv = Real(1) / h;
  const Real g1 = dot(w, u1) * inv, g2 = dot(w, u2) * inv;
  ev.f += h;
  ev.g1 += g1;
  ev.g2 += g2;
  ev.h11 += (dot(u1, u1) - g1 * g1) * inv;
  ev.h12 += (dot(u1, u2) - g1 * g2) * inv;
  ev.h22 += (dot(u2, u2) - g2 * g2) * inv;
}

// h(n) = |D Rᵀ n| alone.
template <class Real>
CG_HD Real support_value(const Ellipsoid<Real>& e, Vec3<Real> n) {
  const Vec3<Real> w = hadamard(e.semi_axes, mul_transpose(e.rotation, n));
  return cg_sqrt(dot(w, w));
}

template <class Real>
CG_HD Evaluation<Real> evaluate(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b, Vec3<Real> r,
                                Vec3<Real> n) {
  Evaluation<Real> ev{};
  ev.n = n;
  plane_space(n, ev.t1, ev.t2);
  add_body(a, ev);  // h_A(−n) = h_A(n), and ∇²h_A is even: A enters exactly as B does
  add_body(b, ev);
  ev.f -= dot(n, r);
  ev.g1 -= dot(ev.t1, r);
  ev.g2 -= dot(ev.t2, r);
  // Riemannian Hessian on the sphere: Tᵀ∇²f T − (n·∇f) I, and n·∇f = f (Euler, f is 1-homogeneous).
  ev.h11 -= ev.f;
  ev.h22 -= ev.f;
  return ev;
}

template <class Real>
struct LocalResult {
  Vec3<Real> n;
  Real f, grad;
  int evaluations;
  bool converged;
  bool merged;  // stopped on reaching the neighbourhood of `known`: the same minimum, not a candidate
};

// Damped Newton from n0: the 2×2 Riemannian Hessian is shifted to be positive definite (λmin ≥ δ), the
// step is capped to a trust radius Δ (radians) that halves on rejection and doubles on success, and the
// new point is normalize(n + s1 t1 + s2 t2). A step is accepted if it lowers f, or — where the change of
// f is below its rounding (near the minimum in fp32) — if it lowers the gradient without raising f
// beyond rounding.
template <class Real>
CG_HD LocalResult<Real> local_minimise(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b, Vec3<Real> r,
                                       Vec3<Real> n0, Real scale, Real tolerance, int max_evaluations,
                                       const Vec3<Real>* known = nullptr) {
  const Real eps = std::numeric_limits<Real>::epsilon();
  const Real gtol = tolerance * scale;
  const Real f_noise = Real(16) * eps * (scale + cg_sqrt(dot(r, r)));
  const Real delta_min = Real(1e-3) * scale;
  Evaluation<Real> ev = evaluate(a, b, r, n0);
  int evaluations = 1;
  Real radius = Real(0.5);
  Real grad = cg_sqrt(ev.g1 * ev.g1 + ev.g2 * ev.g2);
  bool converged = grad <= gtol;
  while (!converged && evaluations < max_evaluations) {
    const Real half_tr = Real(0.5) * (ev.h11 + ev.h22), half_diff = Real(0.5) * (ev.h11 - ev.h22);
    const Real lmin = half_tr - cg_sqrt(half_diff * half_diff + ev.h12 * ev.h12);
    const Real mu = lmin < delta_min ? delta_min - lmin : Real(0);
    const Real p11 = ev.h11 + mu, p22 = ev.h22 + mu, det = p11 * p22 - ev.h12 * ev.h12;
    Real s1 = -(p22 * ev.g1 - ev.h12 * ev.g2) / det;
    Real s2 = -(p11 * ev.g2 - ev.h12 * ev.g1) / det;
    const Real len = cg_sqrt(s1 * s1 + s2 * s2);
    if (len > radius) {
      s1 *= radius / len;
      s2 *= radius / len;
    }
    const Vec3<Real> trial = normalized(ev.n + s1 * ev.t1 + s2 * ev.t2);
    const Evaluation<Real> next = evaluate(a, b, r, trial);
    ++evaluations;
    const Real next_grad = cg_sqrt(next.g1 * next.g1 + next.g2 * next.g2);
    const bool accept = next.f < ev.f - f_noise || (next.f <= ev.f + f_noise && next_grad < grad);
    if (accept) {
      ev = next;
      grad = next_grad;
      converged = grad <= gtol;
      radius = cg_min(Real(2) * radius, Real(1));
      if (known != nullptr && !converged) {
        // Within 1e-4 rad of a minimiser already found (and converged), Newton ends there: stop.
        const Vec3<Real> d = ev.n - *known;
        if (dot(d, d) < Real(1e-8)) return {ev.n, ev.f, grad, evaluations, false, true};
      }
    } else {
      radius *= Real(0.25);
      if (radius < Real(4) * eps) break;  // stalled: no representable progress
    }
  }
  return {ev.n, ev.f, grad, evaluations, converged, false};
}

// Puts a start on the side of a − b (where the global minimiser lies); a zero vector is left alone.
template <class Real>
CG_HD Vec3<Real> towards(Vec3<Real> v, Vec3<Real> r) {
  return dot(v, r) < Real(0) ? -v : v;
}

// The 13 extra directions of the safety net: the 3 world axes, the 4 cube diagonals, the 6 face
// diagonals (up to sign).
template <class Real>
CG_HD Vec3<Real> extra_start(int i) {
  const Real s3 = Real(0.57735026918962576451), s2 = Real(0.70710678118654752440);
  switch (i) {
    case 0:
      return {Real(1), Real(0), Real(0)};
    case 1:
      return {Real(0), Real(1), Real(0)};
    case 2:
      return {Real(0), Real(0), Real(1)};
    case 3:
      return {s3, s3, s3};
    case 4:
      return {s3, s3, -s3};
    case 5:
      return {s3, -s3, s3};
    case 6:
      return {-s3, s3, s3};
    case 7:
      return {s2, s2, Real(0)};
    case 8:
      return {s2, -s2, Real(0)};
    case 9:
      return {s2, Real(0), s2};
    case 10:
      return {s2, Real(0), -s2};
    case 11:
      return {Real(0), s2, s2};
    default:
      return {Real(0), s2, -s2};
  }
}

}  // namespace detail

// The general solve (no dispatch on spheres): see the file comment. `pw` is the result of
// perram_wertheim(a, b) (the caller has it from the filter).
template <class Real>
CG_HD EllipsoidContact<Real> ellipsoid_pair_contact(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b,
                                                    const PerramWertheim<Real>& pw,
                                                    const SolverSettings<Real>& settings = {}) {
  const Vec3<Real> r = a.centre - b.centre;
  const bool coincident = r.x == Real(0) && r.y == Real(0) && r.z == Real(0);
  const Real scale = detail::max_axis(a.semi_axes) + detail::max_axis(b.semi_axes);
  const Real rlen = cg_sqrt(dot(r, r));
  EllipsoidContact<Real> out{};
  out.pw = pw.value;
  out.converged = false;
  out.fallback = false;

  // A later candidate wins only if lower by more than the rounding of f: ties (coincident centres,
  // symmetric pairs) keep the earlier start on every machine.
  const Real f_tie = Real(4) * std::numeric_limits<Real>::epsilon() * (scale + rlen);
  detail::LocalResult<Real> best{};
  bool have = false;
  auto consider = [&](Vec3<Real> start, int cap) {
    detail::LocalResult<Real> res =
        detail::local_minimise(a, b, r, detail::towards(start, r), scale, settings.tolerance, cap,
                               have && best.converged ? &best.n : nullptr);
    out.iterations += res.evaluations;
    if (!res.merged && dot(res.n, r) < Real(0)) {
      // Reflection: f(−n) = f(n) + 2 n·r < f(n), so a minimum on the far side of a − b is never global;
      // its mirror image is a better point, and Newton continues from there.
      res = detail::local_minimise(a, b, r, -res.n, scale, settings.tolerance, cap);
      out.iterations += res.evaluations;
    }
    if (!res.merged && (!have || res.f < best.f - f_tie)) {
      best = res;
      have = true;
    }
  };
  // The fixed ordered start set.
  const int nstarts = settings.starts < 1 ? 1 : (settings.starts > 11 ? 11 : settings.starts);
  for (int s = 0; s < nstarts; ++s) {
    Vec3<Real> start;
    if (s == 0) {
      start = coincident ? Vec3<Real>{Real(1), Real(0), Real(0)} : pw.normal;
    } else if (s == 1) {
      if (coincident) continue;  // (1,0,0) already ran
      start = (Real(1) / rlen) * r;
    } else if (s < 8) {
      start = s < 5 ? column(a.rotation, s - 2) : column(b.rotation, s - 5);
    } else if (s < 10) {  // the two bisectors of the thinnest axes of A and B
      const Vec3<Real> ta = column(a.rotation, detail::min_index(a.semi_axes));
      const Vec3<Real> tb = detail::towards(column(b.rotation, detail::min_index(b.semi_axes)), ta);
      const Vec3<Real> v = s == 8 ? ta + tb : ta - tb;
      if (dot(v, v) < Real(1e-6)) continue;
      start = detail::normalized(v);
    } else {  // the common normal of the longest axes (crossed needles)
      const Vec3<Real> v = cross(column(a.rotation, detail::max_index(a.semi_axes)),
                                 column(b.rotation, detail::max_index(b.semi_axes)));
      if (dot(v, v) < Real(1e-6)) continue;
      start = detail::normalized(v);
    }
    consider(start, settings.max_iterations);
  }
  // The screen: f (value only) at the 4 cube diagonals and 6 face diagonals of each body's frame (up
  // to sign, put towards a − b); Newton from the `screen` lowest. These in-between directions reach
  // basins that no axis start does (two comparable thin axes, one body's thin axis tilted by the other).
  if (settings.screen > 0) {
    const int keep = settings.screen > 4 ? 4 : settings.screen;
    Real top_f[4];
    Vec3<Real> top_n[4];
    int count = 0;
    for (int i = 0; i < 20; ++i) {
      const Mat3<Real>& rot = i < 10 ? a.rotation : b.rotation;
      const Vec3<Real> n = detail::towards(mul(rot, detail::extra_start<Real>(3 + i % 10)), r);
      const Real fv = detail::support_value(a, n) + detail::support_value(b, n) - dot(n, r);
      int pos = count < keep ? count : keep;
      while (pos > 0 && fv < top_f[pos - 1]) {
        if (pos < keep) {
          top_f[pos] = top_f[pos - 1];
          top_n[pos] = top_n[pos - 1];
        }
        --pos;
      }
      if (pos < keep) {
        top_f[pos] = fv;
        top_n[pos] = n;
        if (count < keep) ++count;
      }
    }
    out.iterations += 20 / 4;  // 20 value-only evaluations ≈ 5 full ones
    for (int k = 0; k < count; ++k) consider(top_n[k], settings.max_iterations);
  }
  // The antipode of the best: where a − b is short against the bodies, minima come in near-antipodal
  // pairs (f(−n) = f(n) + 2 n·r) and the deeper one of a pair may be the one no start reached.
  for (int round = 0; round < 2; ++round) {
    const detail::LocalResult<Real> res =
        detail::local_minimise(a, b, r, -best.n, scale, settings.tolerance, settings.max_iterations);
    out.iterations += res.evaluations;
    if (!(res.f < best.f - f_tie)) break;
    best = res;
  }

  // The safety net: the PW sign is exact (a global statement), min f must agree with it beyond rounding.
  const Real eps = std::numeric_limits<Real>::epsilon();
  const Real f_band = Real(64) * eps * (scale + rlen) + settings.tolerance * scale;
  const bool pw_overlap = pw.value<Real(1) - pw.band, pw_apart = pw.value> Real(1) + pw.band;
  const bool inconsistent = (pw_overlap && best.f < -f_band) || (pw_apart && best.f > f_band);
  if (inconsistent || !best.converged) {
    out.fallback = true;
    for (int i = 0; i < 13; ++i) consider(detail::extra_start<Real>(i), settings.max_iterations);
    if (!best.converged) consider(best.n, 4 * settings.max_iterations);  // continuation
  }
  out.converged = best.converged;

  Vec3<Real> n = best.n;
  if (coincident) {  // canonical sign: the first non-zero component positive
    const bool flip = n.x != Real(0) ? n.x < Real(0) : (n.y != Real(0) ? n.y < Real(0) : n.z < Real(0));
    if (flip) n = -n;
  }
  // Support points in the body frames: ∇h(u) = R D² Rᵀu / |D Rᵀu|; A's is taken at −n.
  const Vec3<Real> va = detail::hadamard(a.semi_axes, mul_transpose(a.rotation, n));
  const Vec3<Real> vb = detail::hadamard(b.semi_axes, mul_transpose(b.rotation, n));
  const Real ha = cg_sqrt(dot(va, va)), hb = cg_sqrt(dot(vb, vb));
  out.local_point_a = (Real(-1) / ha) * detail::hadamard(a.semi_axes, va);
  out.local_point_b = (Real(1) / hb) * detail::hadamard(b.semi_axes, vb);
  out.geometry.normal_on_b = n;
  out.geometry.distance = dot(n, r) - (ha + hb);
  out.geometry.position_on_a = a.centre + mul(a.rotation, out.local_point_a);
  out.geometry.position_on_b = b.centre + mul(b.rotation, out.local_point_b);
  return out;
}

// ---------------------------------------------------------------------------------------------------
// Sphere–ellipsoid.

template <class Real>
struct ClosestPoint {
  Vec3<Real> point;   // on the surface, body frame
  Vec3<Real> normal;  // outward unit normal there, body frame
  Real distance;      // signed: > 0 outside, < 0 inside
  int iterations;
  bool converged;
};

// The closest surface point of the axis-aligned ellipsoid with semi-axes e to the point p (body frame).
// x_i = e_i² p_i / (e_i² + t) with t the largest root of Σ (e_i p_i / (e_i² + t))² = 1 on t > −e_min²
// (Eberly, "Distance from a point to an ellipse, an ellipsoid, or a hyperellipsoid"): that root is the
// global closest point, inside or outside. In τ = t + e_min² the denominators are δ_i + τ with
// δ_i = e_i² − e_min² exact-ish and ≥ 0, so nothing cancels near the pole. Newton runs on
// ψ(τ) = 1/√S(τ) − 1 (nearly linear near the pole), safeguarded by the bracket (0, |e∘p|].
// Degenerate case (p has no component along the smallest axis and S(0) ≤ 1): τ = 0 and the point lies
// on the rim; its component along the smallest axis is taken positive (then the first such axis).
template <class Real>
CG_HD ClosestPoint<Real> ellipsoid_closest_point(Vec3<Real> e, Vec3<Real> p) {
  const Real eps = std::numeric_limits<Real>::epsilon();
  const Real ea[3] = {e.x, e.y, e.z}, pa[3] = {p.x, p.y, p.z};
  int k = 0;
  if (ea[1] < ea[k]) k = 1;
  if (ea[2] < ea[k]) k = 2;
  Real delta[3], q[3];
  bool pole = false;
  Real qq = Real(0);
  for (int i = 0; i < 3; ++i) {
    delta[i] = (ea[i] - ea[k]) * (ea[i] + ea[k]);
    q[i] = ea[i] * pa[i];
    qq += q[i] * q[i];
    if (delta[i] == Real(0) && q[i] != Real(0)) pole = true;
  }
  const Real inside_measure = (pa[0] / ea[0]) * (pa[0] / ea[0]) + (pa[1] / ea[1]) * (pa[1] / ea[1]) +
                              (pa[2] / ea[2]) * (pa[2] / ea[2]);
  ClosestPoint<Real> out{};
  Real x[3];
  bool done = false;
  if (!pole) {
    Real s0 = Real(0);
    for (int i = 0; i < 3; ++i)
      if (delta[i] > Real(0)) s0 += (q[i] / delta[i]) * (q[i] / delta[i]);
    if (s0 <= Real(1)) {  // degenerate: τ = 0
      Real rest = Real(0);
      for (int i = 0; i < 3; ++i) {
        x[i] = delta[i] > Real(0) ? ea[i] * q[i] / delta[i] : Real(0);
        rest += (x[i] / ea[i]) * (x[i] / ea[i]);
      }
      x[k] = ea[k] * cg_sqrt(detail::cg_max(Real(0), Real(1) - rest));
      out.converged = true;
      done = true;
    }
  }
  if (!done) {
    Real lo = Real(0), hi = cg_sqrt(qq), tau = hi;
    const int cap = 64;
    int it = 0;
    for (; it < cap; ++it) {
      Real s = Real(0), ds = Real(0);
      for (int i = 0; i < 3; ++i) {
        const Real den = delta[i] + tau, v = q[i] / den;
        s += v * v;
        ds -= Real(2) * v * v / den;
      }
      const Real rs = Real(1) / cg_sqrt(s);
      const Real psi = rs - Real(1), dpsi = Real(-0.5) * rs * ds / s;  // ψ' > 0
      if (psi == Real(0)) {
        out.converged = true;
        break;
      }
      if (psi < Real(0)) {
        lo = tau;
      } else {
        hi = tau;
      }
      Real next = tau - psi / dpsi;
      if (!(next > lo && next < hi)) next = Real(0.5) * (lo + hi);
      const Real step = detail::cg_abs(next - tau);
      tau = next;
      if (step <= Real(4) * eps * tau || hi - lo <= Real(4) * eps * hi) {
        out.converged = true;
        ++it;
        break;
      }
    }
    out.iterations = it;
    for (int i = 0; i < 3; ++i) x[i] = ea[i] * q[i] / (delta[i] + tau);
  }
  out.point = {x[0], x[1], x[2]};
  out.normal =
      detail::normalized(Vec3<Real>{x[0] / (ea[0] * ea[0]), x[1] / (ea[1] * ea[1]), x[2] / (ea[2] * ea[2])});
  const Vec3<Real> d = p - out.point;
  const Real len = cg_sqrt(dot(d, d));
  out.distance = inside_measure > Real(1) ? len : -len;
  return out;
}

// A sphere (centre c, radius ρ) against an ellipsoid, with the semantics of the file comment:
// sphere_is_a says which of the two is body A (the smaller id). Equal semi-axes: sphere_sphere_contact.
template <class Real>
CG_HD EllipsoidContact<Real> sphere_ellipsoid_contact(const Sphere<Real>& s, const Ellipsoid<Real>& e,
                                                      bool sphere_is_a) {
  EllipsoidContact<Real> out{};
  out.pw = Real(-1);
  out.converged = true;
  out.fallback = false;
  const Vec3<Real> ax = e.semi_axes;
  if (ax.x == ax.y && ax.y == ax.z) {
    const Sphere<Real> se{e.centre.x, e.centre.y, e.centre.z, ax.x};
    out.geometry = sphere_is_a ? sphere_sphere_contact(s, se) : sphere_sphere_contact(se, s);
    const Vec3<Real> ca = sphere_is_a ? s.centre() : e.centre, cb = sphere_is_a ? e.centre : s.centre();
    out.local_point_a = out.geometry.position_on_a - ca;
    out.local_point_b = out.geometry.position_on_b - cb;
    if (sphere_is_a) {
      out.local_point_b = mul_transpose(e.rotation, out.local_point_b);
    } else {
      out.local_point_a = mul_transpose(e.rotation, out.local_point_a);
    }
    return out;
  }
  const Vec3<Real> rel = s.centre() - e.centre;
  ClosestPoint<Real> cp = ellipsoid_closest_point(ax, mul_transpose(e.rotation, rel));
  out.iterations = cp.iterations;
  out.converged = cp.converged;
  Vec3<Real> nu = mul(e.rotation, cp.normal);  // outward normal of the ellipsoid, world
  if (rel.x == Real(0) && rel.y == Real(0) && rel.z == Real(0)) {
    // Coincident centres: ±x are both closest; the canonical sign of the file comment on n.
    const Vec3<Real> n = sphere_is_a ? nu : -nu;
    const bool flip = n.x != Real(0) ? n.x < Real(0) : (n.y != Real(0) ? n.y < Real(0) : n.z < Real(0));
    if (flip) {
      cp.point = -cp.point;
      cp.normal = -cp.normal;
      nu = -nu;
    }
  }
  const Vec3<Real> on_e = e.centre + mul(e.rotation, cp.point);
  out.geometry.distance = cp.distance - s.r;
  if (sphere_is_a) {
    out.geometry.normal_on_b = nu;
    out.geometry.position_on_b = on_e;
    out.geometry.position_on_a = s.centre() - s.r * nu;
    out.local_point_a = -s.r * nu;
    out.local_point_b = cp.point;
  } else {
    out.geometry.normal_on_b = -nu;
    out.geometry.position_on_a = on_e;
    out.geometry.position_on_b = s.centre() - s.r * nu;
    out.local_point_a = cp.point;
    out.local_point_b = -s.r * nu;
  }
  return out;
}

// ---------------------------------------------------------------------------------------------------
// The entry point for a candidate pair of ellipsoids: two spheres take the closed form, one sphere the
// sphere–ellipsoid path, otherwise the PW filter then the solve. `contact` tells the caller whether to
// emit a row (distance ≤ 0); where the PW filter rejects, the geometry is not computed.
template <class Real>
struct EllipsoidPairResult {
  EllipsoidContact<Real> contact;
  bool in_contact;
};

template <class Real>
CG_HD EllipsoidPairResult<Real> ellipsoid_contact(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b,
                                                  const SolverSettings<Real>& settings = {}) {
  const Vec3<Real> ea = a.semi_axes, eb = b.semi_axes;
  const bool sa = ea.x == ea.y && ea.y == ea.z, sb = eb.x == eb.y && eb.y == eb.z;
  EllipsoidPairResult<Real> res{};
  if (sa || sb) {
    const Ellipsoid<Real>& sph = sa ? a : b;
    res.contact = sphere_ellipsoid_contact(
        Sphere<Real>{sph.centre.x, sph.centre.y, sph.centre.z, sph.semi_axes.x}, sa ? b : a, sa);
    // A body given as an ellipsoid with equal axes still has an orientation: its local point too.
    if (sa)
      res.contact.local_point_a = mul_transpose(a.rotation, res.contact.geometry.position_on_a - a.centre);
    if (sb)
      res.contact.local_point_b = mul_transpose(b.rotation, res.contact.geometry.position_on_b - b.centre);
  } else {
    const PerramWertheim<Real> pw = perram_wertheim(a, b);
    if (!pw_may_touch(pw)) {
      res.contact.pw = pw.value;
      res.contact.converged = true;
      res.contact.iterations = 0;
      res.contact.geometry.distance = Real(1);  // not computed; positive
      res.in_contact = false;
      return res;
    }
    res.contact = ellipsoid_pair_contact(a, b, pw, settings);
  }
  res.in_contact = res.contact.geometry.distance <= Real(0);
  return res;
}

}  // namespace cg
