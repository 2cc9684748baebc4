#pragma once
// The exact reference for ellipsoid contacts (issue #12; exact.hpp says what "exact" means). It
// shares no code with the engine's narrow phase (kernels/core/ellipsoid_contact.hpp, quat.hpp): its
// own long-double vectors, rotation by the Hamilton product q v q*, and different algorithms:
//   - min f by brute force: f at every point of a Fibonacci sphere (default 20 000 directions, spacing
//     ≈ 0.025 rad) and the ± principal axes of both bodies; the lowest well-separated samples are refined
//     by Newton in a gnomonic chart (analytic gradient, finite-difference Hessian, backtracking) and
//     the lowest refined value wins;
//   - the Perram–Wertheim function by golden-section search (not Newton) with Cramer's-rule solves.
// f(n) = h_A(n) + h_B(n) − n·(a − b) with h_X(u) = |D_X R_Xᵀ u|; distance = −min f.
#include <array>

#include "reference/exact.hpp"

namespace cg::exact {

// A body: centre, semi-axes, and its three local axes in the world (axis[k] = q e_k q*).
struct Body {
  V centre;
  V axes;
  std::array<V, 3> axis;
};

// q v q* for a unit-normalised q = (w, x, y, z), by two Hamilton products.
inline V rotate_hamilton(std::array<LD, 4> q, V v) {
  const LD n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (auto& c : q) c /= n;
  // p = q (0, v)
  const LD pw = -(q[1] * v.x + q[2] * v.y + q[3] * v.z);
  const LD px = q[0] * v.x + q[2] * v.z - q[3] * v.y;
  const LD py = q[0] * v.y + q[3] * v.x - q[1] * v.z;
  const LD pz = q[0] * v.z + q[1] * v.y - q[2] * v.x;
  // p q* with q* = (w, −x, −y, −z): vector part
  return {-pw * q[1] + px * q[0] - py * q[3] + pz * q[2], -pw * q[2] + py * q[0] - pz * q[1] + px * q[3],
          -pw * q[3] + pz * q[0] - px * q[2] + py * q[1]};
}

inline Body make_body(V centre, V axes, std::array<LD, 4> q) {
  return {centre,
          axes,
          {rotate_hamilton(q, {1, 0, 0}), rotate_hamilton(q, {0, 1, 0}), rotate_hamilton(q, {0, 0, 1})}};
}

inline LD body_comp(const Body& b, V u, int k) { return dotp(b.axis[k], u); }
inline LD semi(const Body& b, int k) { return k == 0 ? b.axes.x : (k == 1 ? b.axes.y : b.axes.z); }

inline LD support_value(const Body& b, V u) {
  LD s = 0;
  for (int k = 0; k < 3; ++k) {
    const LD c = semi(b, k) * body_comp(b, u, k);
    s += c * c;
  }
  return std::sqrt(s);
}

// ∇h(u) = Σ_k axis_k e_k² (axis_k·u) / h: the support point relative to the centre.
inline V support_point(const Body& b, V u) {
  const LD h = support_value(b, u);
  V p{0, 0, 0};
  for (int k = 0; k < 3; ++k) p = add(p, scale(semi(b, k) * semi(b, k) * body_comp(b, u, k) / h, b.axis[k]));
  return p;
}

struct Pair {
  Body a, b;
  V r;  // a − b, exact in long double from the caller's centres
};

inline LD f_value(const Pair& p, V n) { return support_value(p.a, n) + support_value(p.b, n) - dotp(n, p.r); }
inline V f_gradient(const Pair& p, V n) {
  return sub(add(support_point(p.a, n), support_point(p.b, n)), p.r);
}

struct Reference {
  V n;          // the global minimiser, B → A
  LD distance;  // −min f
  V position_on_a, position_on_b;
  LD second_gap;  // f of the best refined minimum at least 0.05 rad away, minus min f (∞ if none)
  int minima;     // distinct refined local minima found
};

// The global minimiser of f for the pair, from `samples` Fibonacci directions (see the file comment).
Reference exact_contact(const Pair& p, int samples = 20000);

// Perram–Wertheim F = max_λ λ(1−λ) rᵀ[(1−λ)A + λB]⁻¹ r, A = Σ_k e_k² axis_k axis_kᵀ, by golden-section
// search on the concave F (200 steps: the bracket shrinks below long-double resolution). F < 1: apart.
LD pw_exact(const Pair& p);

}  // namespace cg::exact
