#pragma once
// The narrow phase's decision, shared by both backends: is a candidate pair a contact, and its row.
// The one place a shape-specific test slots in (ellipsoids, a mixed-precision narrow phase): the pair
// stage only proposes candidates, narrow_decide() decides.
#include "core/contact.hpp"

namespace cg {

template <class Real>
struct NarrowDecision {
  bool contact;          // the pair is a contact (d <= ra + rb for spheres: touching counts)
  ContactRow<Real> row;  // world frame; meaningful only when contact
};

// Spheres: the contact test of the pair stage (spheres_touch, no square root) decides, so a candidate
// list filtered by it holds contacts only (narrow_may_reject() false) and the decision is the same
// bits on both backends. The row is computed only for a contact.
template <class Real>
CG_HD NarrowDecision<Real> narrow_decide(const Sphere<Real>& a, const Sphere<Real>& b,
                                         const Vec3<double>& origin, bool full) {
  NarrowDecision<Real> d{};
  d.contact = spheres_touch(a, b);
  if (d.contact) d.row = sphere_contact_row(a, b, origin, full);
  return d;
}

// How the pair stage filtered its candidates: with the sphere test itself (every candidate is a
// contact), or by the cell rule only (every pair of bodies sharing their first common cell: a looser
// filter, for tests of the rejecting path and for candidate lists kept across calls with a skin).
// bounding_spheres: the sphere test on the bounding spheres of bodies that are not all spheres (scenes
// with ellipsoids): the same pair-stage filter as spheres_touch, but the narrow stage decides (the
// shapes may not touch where their bounding spheres do).
enum class CandidateFilter { spheres_touch, cells, bounding_spheres };

// True when narrow_decide() may reject a candidate of this filter: the narrow stage then counts, scans
// and compacts; else it writes one row per candidate (no scan).
CG_HD constexpr bool narrow_may_reject(CandidateFilter f) { return f != CandidateFilter::spheres_touch; }

// True when the pair stage keeps only candidates whose (bounding) spheres touch (spheres_touch()).
CG_HD constexpr bool candidates_touch(CandidateFilter f) { return f != CandidateFilter::cells; }

}  // namespace cg
