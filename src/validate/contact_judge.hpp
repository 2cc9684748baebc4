#pragma once
// The judge of `contactgrid validate`: is one contact answer the contact of two convex bodies?
// Long-double math of its own, sharing no code with the engine's narrow phase (kernels/core/*), so it
// can decide between the engine and Bullet when they disagree.
//
// A body X (sphere or ellipsoid) has centre x, world axes R_X (columns: q e_k q* for its unit
// quaternion q, docs/FORMAT.md §1) and semi-axes D_X = diag(s_0, s_1, s_2) (a sphere: D = r·I, R = I).
// Its support function about the centre is h_X(u) = |D_X R_Xᵀ u|, with gradient (the support offset)
// s_X(u) = R_X D_X² R_Xᵀ u / h_X(u). For a pair (A, B) and unit n (from B towards A)
//     f(n) = h_A(−n) + h_B(n) − n·(a − b),
// distance = −min f over unit n (the global minimum), n = the minimiser, and the points are the
// support points position_on_a = a + s_A(−n), position_on_b = b + s_B(n) (docs/FORMAT.md §3).
//
// An answer (position_on_a, position_on_b, normal_on_b, distance) passes when, within `tol` (a length):
//   1. n is a unit vector (|1 − |n|| ≤ 1e-6 + tol / L, L the larger bounding radius);
//   2. each point lies on its own body's surface (first-order distance to the surface ≤ tol);
//   3. the surface normal there is parallel to −n on A and +n on B (angle ≤ tol / ρ, ρ the body's
//      smallest radius of curvature: a point moved by tol along the surface turns its normal so far);
//   4. position_on_a = position_on_b + n·distance (|difference| ≤ tol);
//   5. no direction is deeper: min f over a cap of directions around n, the principal axes of both
//      bodies, the centre line and a Fibonacci sphere of 512 directions, each of the best distinct
//      samples refined by Newton on the sphere, is not below f(n) − tol (the minimum is global).
// The first condition that fails is the verdict's reason.
#include <array>
#include <string>

#include "core/vec3.hpp"

namespace cg::judge {

using LD = long double;
using V = Vec3<LD>;

struct Body {
  V centre;
  std::array<LD, 3> semi;  // semi-axes along the body's local x, y, z
  std::array<V, 3> axis;   // the local axes in the world frame (columns of R)

  LD bounding() const;          // the largest semi-axis
  LD curvature_radius() const;  // the smallest radius of curvature, s_min² / s_max
  LD support_value(V u) const;  // h(u), u unit
  V support_offset(V u) const;  // s(u) = ∇h(u), u unit: the support point minus the centre
};

Body sphere(Vec3<double> centre, double radius);
// `q` = (w, x, y, z), normalised here (the scene reader accepts | |q| − 1 | ≤ 1e-5).
Body ellipsoid(Vec3<double> centre, Vec3<double> semi_axes, std::array<double, 4> q);

// f(n) for unit n.
LD contact_function(const Body& a, const Body& b, V n);

struct Minimum {
  V n;   // the minimiser, unit, from B towards A
  LD f;  // min f = −distance
};
// The global minimum of f as in condition 5; `near` (optional, unit) adds a cap of samples around it.
Minimum global_minimum(const Body& a, const Body& b, const V* near = nullptr);

struct Answer {
  Vec3<double> position_on_a, position_on_b, normal_on_b;
  double distance;
};

struct Verdict {
  bool ok = false;
  std::string reason;   // empty when ok; else the first failed condition, with its numbers
  double distance = 0;  // −min f found by the judge (the exact distance)
};

// Judges one answer for the pair (a, b) with the length tolerance `tol` (> 0).
Verdict judge_answer(const Body& a, const Body& b, const Answer& answer, double tol);

}  // namespace cg::judge
