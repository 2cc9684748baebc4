#pragma once
// The Perram–Wertheim contact function of two ellipsoids: the exact overlap test and the first start
// of the contact solve (core/ellipsoid_contact.hpp: the overview).
#include "core/ellipsoid.hpp"

namespace cg {

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

}  // namespace cg
