#pragma once
// The contact of a sphere and an ellipsoid: the closest point by a 1-D root find on the normal
// equation (core/ellipsoid_contact.hpp: the overview).
#include "core/ellipsoid.hpp"

namespace cg {

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

}  // namespace cg
