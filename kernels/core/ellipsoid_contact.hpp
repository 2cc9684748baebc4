#pragma once
// Narrow phase for ellipsoid pairs and sphere–ellipsoid pairs (issue #12), shared by both backends.
//
// Semantics (docs/FORMAT.md §3, Bullet's convex–convex contacts). For a unit direction n (from B towards A)
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
//   0. separated_along_centres(): the centre line as a separating axis, two support values; rejects
//      most of the bounding-sphere candidates that are apart before PW runs.
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
//      from the antipode of the best (when a − b is short, minima come in near-antipodal pairs). Each
//      start's run is a function of that start alone (newton_run), so a batch of them may run side by
//      side — the device's whole-set kernel gives each start a lane of a lane group (SerialRuns,
//      WarpRuns; no run stops on another's result, which would chain every run to the one before it).
//      The smallest f wins; a later candidate must be lower by more than the rounding of f (ties keep
//      the earlier start). Each ingredient closes a class of misses of a stress run against the exact
//      reference (deep overlaps — a centre inside the other body — and random overlaps, axis ratios
//      3–100, double): reflection the minima with n·(a − b) < 0, the antipode run antipodal pairs, then
//      the bisector starts and the screen; the unit tests keep those pairs, and the whole set misses
//      none of 48 000 fresh ones. 5 axis starts alone miss deep overlaps routinely (A's centre inside B
//      needs B's axes).
//      The certificates (ellipsoid_certificate.hpp, with their proofs): a converged minimum n with
//      t = f(n) is global to within the solver tolerance if t < 0 (separated), or
//      t ≤ e_A²/h_A(n) + e_B²/h_B(n) (e the smallest semi-axis: two balls tangent inside at the contact
//      points), or an inner ellipsoid of A ⊕ (−B) touching it at n holds the ball of radius t; then the
//      rest of the set is skipped: separated and shallow pairs — nearly every contact of a packing —
//      and nearly all deep overlaps cost one start (0.35 % of a random scene's candidates do not);
//      SolverSettings::certify = false runs the whole set (tests compare the two bit for bit).
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
// The general solve returns the minimiser with the contact; contact_at_normal() rebuilds the same
// contact from it (the device's fill pass; SolveScope::first_start lets a first pass settle the
// certified pairs and leave the rest to a second).
//
// Files: ellipsoid.hpp (types, settings, 3×3 helpers), perram_wertheim.hpp (1.), ellipsoid_solve.hpp
// (2., 3.), ellipsoid_certificate.hpp (2.'s certificates), sphere_ellipsoid.hpp (4.); this file: the
// entry point for a candidate pair (0.).
#include "core/ellipsoid_solve.hpp"
#include "core/sphere_ellipsoid.hpp"

namespace cg {

// ---------------------------------------------------------------------------------------------------
// The entry point for a candidate pair of ellipsoids: two spheres take the closed form, one sphere the
// sphere–ellipsoid path, otherwise the PW filter then the solve. `contact` tells the caller whether to
// emit a row (distance ≤ 0); where the PW filter rejects, the geometry is not computed.
template <class Real>
struct EllipsoidPairResult {
  EllipsoidContact<Real> contact;
  bool in_contact;
};

// The centre line as a separating axis: f(u) < 0 at u = (a − b)/|a − b| proves min f < 0, the pair
// apart, for two support values (PW costs ~5 solves of a 3×3 system). Beyond the rounding of f only,
// so that a rejected pair is one the solve would also find apart. In a random scene of semi-axes
// U[0.25, 1] it rejects 88 % of the bounding-sphere candidates that PW rejects.
template <class Real>
CG_HD bool separated_along_centres(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b) {
  const Vec3<Real> r = a.centre - b.centre;
  const Real len2 = dot(r, r);
  if (!(len2 > Real(0))) return false;
  const Real len = cg_sqrt(len2);
  const Vec3<Real> u = (Real(1) / len) * r;
  const Real reach = detail::support_value(a, u) + detail::support_value(b, u);
  const Real noise = Real(16) * std::numeric_limits<Real>::epsilon() *
                     (detail::max_axis(a.semi_axes) + detail::max_axis(b.semi_axes) + len);
  return len - reach > noise;
}

// `carry` (ellipsoid_solve.hpp: FirstStart): first_start_cheap keeps its first start there where it
// leaves the pair incomplete; first_start given one goes on from it (the centre line and the PW filter
// passed for it already: neither runs again).
template <SolveScope Scope = SolveScope::whole, class Real, class Runs = SerialRuns>
CG_HD EllipsoidPairResult<Real> ellipsoid_contact(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b,
                                                  const SolverSettings<Real>& settings = {},
                                                  const Runs& runs = {}, FirstStart<Real>* carry = nullptr) {
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
  } else if constexpr (Scope == SolveScope::none) {
    res.contact.complete = false;
    res.in_contact = false;
    return res;
  } else {
    auto apart = [&](Real pw_value) {
      res.contact.pw = pw_value;
      res.contact.converged = true;
      res.contact.iterations = 0;
      res.contact.geometry.distance = Real(1);  // not computed; positive
      res.in_contact = false;
      return res;
    };
    PerramWertheim<Real> pw{};
    if (Scope == SolveScope::first_start && carry) {
      pw.value = carry->pw_value;
      pw.band = carry->pw_band;
    } else {
      if (separated_along_centres(a, b)) return apart(Real(-1));
      pw = perram_wertheim(a, b);
      if (!pw_may_touch(pw)) return apart(pw.value);
    }
    res.contact = ellipsoid_pair_contact<Scope>(a, b, pw, settings, runs, carry);
    if (!res.contact.complete) {  // first start uncertified: no geometry yet
      res.in_contact = false;
      return res;
    }
  }
  res.in_contact = res.contact.geometry.distance <= Real(0);
  return res;
}

}  // namespace cg
