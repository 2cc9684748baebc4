#pragma once
// The certificates of globality of the ellipsoid contact solve (core/ellipsoid_contact.hpp: the
// overview). Each takes a converged local minimiser n of f (value t = f(n), tangential gradient
// g = |P∇f(n)|) and proves min f ≥ t − g over the whole unit sphere: n is the global minimiser to
// within the solver tolerance, and the rest of the start set can be skipped.
//
// Notation: M_X = D_X R_Xᵀ, so h_X(u) = |M_X u|; r = a − b; f(m) = h_A(m) + h_B(m) − m·r (h is even).
// At n: M_A n = h_A·u_A, M_B n = h_B·u_B (unit u_X), ∇f(n) = M_Aᵀu_A + M_Bᵀu_B − r, n·∇f = t (Euler).
//
// 1. Separated (t < 0): f is convex and 1-homogeneous, so a negative local minimum over the sphere
//    is the global one.
// 2. Two balls (inscribed_ball_reach). Lemma: for an ellipsoid with smallest semi-axis e, the ball
//    of radius e²/h(u) tangent inside at the boundary point with outward normal u lies inside it.
//    (Body frame, G = D⁻², boundary point x, u = Gx/|Gx|, |Gx| = 1/h(u): the quadratic
//    ψ(y) = yᵀGy − 1 − (|y − c|² − ρ²)/e² with c = x − e²Gx, ρ = |x − c| is concave since every
//    1/e_i² ≤ 1/e², and ∇ψ(x) = 0, ψ(x) = 0, so ψ ≤ 0: every point of the ball has yᵀGy ≤ 1.)
//    A's contact point p_A has outward normal −n, B's p_B has n. Split t = δA + δB with δA ≤ eA²/h_A(n),
//    δB ≤ eB²/h_B(n) and take those balls, centres q_A = p_A + δA·n, q_B = p_B − δB·n. For every unit m,
//    h_A(m) ≥ −m·(q_A − a) + δA and h_B(m) ≥ m·(q_B − b) + δB, so f(m) ≥ t + m·(q_B − q_A), and
//    q_B − q_A = ∇f(n) − t·n = P∇f(n). Holds whenever t ≤ eA²/h_A(n) + eB²/h_B(n); this reach is at
//    least ρ = Σ e_min²/e_max (the rolling-ball bound) and is the thin half-axes' sum where the contact
//    is on the flat sides.
// 3. An inner ellipsoid of A ⊕ (−B) (inner_ellipsoid_certificate). For any orthogonal U,
//    h_A(m) + h_B(m) = |M_A m| + |U M_B m| ≥ |(M_A + U M_B) m| (triangle inequality): the ellipsoid E
//    with matrix M_E = M_A + U M_B lies inside A ⊕ (−B), and f ≥ f_E (f_E: f with E for A ⊕ (−B)).
//    Taking U u_B = u_A makes E touch A ⊕ (−B) at n: f_E(n) = t and ∇f_E(n) = ∇f(n). By the lemma for E
//    (smallest semi-axis σ_min(M_E)), if t ≤ σ_min(M_E)²/h_E(n) with h_E(n) = h_A(n) + h_B(n), then
//    min f ≥ min f_E ≥ t − g as in 2. U is free up to a turn ψ about u_A; eight turns ψ = kπ/4 are
//    tried. With frames (u_A, p_A, q_A) and (u_B, p_B, q_B), F_Aᵀ M_E has the rows
//      w1 = M_Aᵀu_A + M_Bᵀu_B,  w2 = M_Aᵀp_A + cosψ·M_Bᵀp_B − sinψ·M_Bᵀq_B,
//      w3 = M_Aᵀq_A + sinψ·M_Bᵀp_B + cosψ·M_Bᵀq_B,
//    and σ_min(M_E)² is the smallest eigenvalue of their Gram matrix. This settles most deep overlaps
//    that 2 does not (89 % of the rest, CPU sample of the bench scene's law, semi-axes U[0.25, 1]).
// Rounding: the certificates compare t + f_noise with the bound (f_noise: f's rounding); the bound
// is continuous in t, so an error of ε in either side weakens min f ≥ t − g by O(ε) only. The
// eigenvalue is a proved lower bound (smallest_eigenvalue_below).
#include <limits>

#include "core/contact.hpp"
#include "core/ellipsoid.hpp"

namespace cg::detail {

// 2: the reach of the two-ball certificate at n (the radii of the largest balls tangent inside at the
// two contact points).
template <class Real>
CG_HD Real inscribed_ball_reach(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b, Vec3<Real> n) {
  const Real ea = min_axis(a.semi_axes), eb = min_axis(b.semi_axes);
  return ea * ea / support_value(a, n) + eb * eb / support_value(b, n);
}

// A lower bound of the smallest eigenvalue of the symmetric positive semidefinite g, proved: on
// λ < λ_min the characteristic polynomial p(λ) = det(g − λI) is positive, decreasing and convex, so
// Newton from λ = 0 rises monotonically towards λ_min (each tangent's zero lies below the root);
// twelve steps at most (linear convergence only at a repeated root, where the bound stays below).
// The result, lowered by 64 ulps of the trace, is accepted only if the Cholesky factorisation of
// g − λI completes with positive pivots: being backward stable, that proves g − λI positive definite
// up to a perturbation of a few ulps of |g| (the rounding g itself carries). 0 otherwise (no
// certificate).
template <class Real>
CG_HD Real smallest_eigenvalue_below(const Sym3<Real>& g) {
  const Real c2 = g.xx + g.yy + g.zz;
  const Real c1 = (g.xx * g.yy - g.xy * g.xy) + (g.xx * g.zz - g.xz * g.xz) + (g.yy * g.zz - g.yz * g.yz);
  Real c0;
  adjugate(g, c0);
  if (!(c0 > Real(0)) || !(c1 > Real(0))) return Real(0);
  Real lambda = Real(0);
  for (int i = 0; i < 12; ++i) {
    const Real p = c0 - lambda * (c1 - lambda * (c2 - lambda));
    const Real dp = lambda * (Real(2) * c2 - Real(3) * lambda) - c1;
    if (!(dp < Real(0))) break;
    const Real next = lambda - p / dp;
    if (!(next > lambda)) break;
    lambda = next;
  }
  lambda -= Real(64) * std::numeric_limits<Real>::epsilon() * c2;
  if (!(lambda > Real(0))) return Real(0);
  // Cholesky (LDLᵀ) of g − λI
  const Real d1 = g.xx - lambda;
  if (!(d1 > Real(0))) return Real(0);
  const Real l21 = g.xy / d1, l31 = g.xz / d1;
  const Real d2 = (g.yy - lambda) - l21 * g.xy;
  if (!(d2 > Real(0))) return Real(0);
  const Real e32 = g.yz - l21 * g.xz;
  const Real d3 = (g.zz - lambda) - l31 * g.xz - (e32 / d2) * e32;
  return d3 > Real(0) ? lambda : Real(0);
}

// 3: true if an inner ellipsoid of A ⊕ (−B) touching it at n proves t = f(n) global (t ≥ 0 here;
// f_noise: the rounding of f).
template <class Real>
CG_HD bool inner_ellipsoid_certificate(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b, Vec3<Real> n,
                                       Real t, Real f_noise) {
  const Vec3<Real> ya = hadamard(a.semi_axes, mul_transpose(a.rotation, n));  // M_A n
  const Vec3<Real> yb = hadamard(b.semi_axes, mul_transpose(b.rotation, n));
  const Real ha = cg_sqrt(dot(ya, ya)), hb = cg_sqrt(dot(yb, yb));
  const Vec3<Real> ua = (Real(1) / ha) * ya, ub = (Real(1) / hb) * yb;
  Vec3<Real> pa, qa, pb, qb;
  plane_space(ua, pa, qa);
  plane_space(ub, pb, qb);
  // M_Xᵀ v = R_X D_X v
  auto mt = [](const Ellipsoid<Real>& e, Vec3<Real> v) { return mul(e.rotation, hadamard(e.semi_axes, v)); };
  const Vec3<Real> w1 = mt(a, ua) + mt(b, ub);
  const Vec3<Real> va2 = mt(a, pa), va3 = mt(a, qa), vb2 = mt(b, pb), vb3 = mt(b, qb);
  const Real need = (t + f_noise) * (ha + hb);  // σ_min² must reach t·h_E(n)
  const Real w11 = dot(w1, w1);
  const Real h = Real(0.70710678118654752440);
  for (int k = 0; k < 8; ++k) {  // ψ = kπ/4: (cos, sin) exact where they can be
    const int q = k & 3;
    const Real sign = k < 4 ? Real(1) : Real(-1);
    const Real c = sign * (q == 0 ? Real(1) : q == 1 ? h : q == 2 ? Real(0) : -h);
    const Real s = sign * (q == 0 ? Real(0) : q == 2 ? Real(1) : h);
    const Vec3<Real> w2 = va2 + c * vb2 - s * vb3;
    const Vec3<Real> w3 = va3 + s * vb2 + c * vb3;
    const Sym3<Real> gram{w11, dot(w2, w2), dot(w3, w3), dot(w1, w2), dot(w1, w3), dot(w2, w3)};
    if (need <= smallest_eigenvalue_below(gram)) return true;
  }
  return false;
}

}  // namespace cg::detail
