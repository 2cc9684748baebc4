#pragma once
// The narrow phase's decision, shared by both backends: is a candidate pair a contact, and its row.
// The one place a shape- or precision-specific test slots in: the pair stage only proposes candidates,
// narrow_decide() decides.
//
// Where each precision mode takes its numbers (README "Choosing a precision"):
//   fp64, mixed  decision: spheres_touch on the frame-local doubles Real(world − origin), exactly the
//                bits of fp64's pack, so fp64's pair stage and mixed's narrow stage decide alike;
//                row: from the WORLD doubles (world_sphere_row): the centre difference a − b of two
//                world doubles (exact when they are within a factor 2 of each other, Sterbenz; else
//                one rounding), the points world + offset. No rounding from the frame.
//   fp32         decision and row on the frame-local floats of pack; a pair whose local centres are
//                closer than fp32 resolves (fp32_resolves false) takes the fp64 row from the world
//                doubles, rounded once to float, and is counted (NarrowFlags::fp64_rows).
#include <type_traits>

#include "core/contact.hpp"

namespace cg {

// Flags of one candidate, counted into EngineStats: the ellipsoid solver's (ellipsoid pairs only) and
// the fp32 rows recomputed in fp64.
struct NarrowFlags {
  std::uint32_t fallbacks = 0, unconverged = 0, fp64_rows = 0;
};

// The bodies as the narrow stage reads them, by body index.
template <class Real>
struct NarrowBodies {
  const Sphere<Real>* spheres;  // fp32: pack's local spheres; fp64 and mixed: not read (may be null)
  const double* position;       // world centres, x y z of body i at 3i (host or DEVICE memory)
  const double* radius;         // world (bounding) radii
  Vec3<double> origin;          // the frame's origin
};

template <class Real>
CG_HD Vec3<double> world_centre(const NarrowBodies<Real>& w, std::uint32_t i) {
  const std::size_t i3 = 3 * std::size_t(i);
  return {w.position[i3], w.position[i3 + 1], w.position[i3 + 2]};
}

// Body i in the world frame, double.
template <class Real>
CG_HD Sphere<double> world_sphere(const NarrowBodies<Real>& w, std::uint32_t i) {
  const Vec3<double> c = world_centre(w, i);
  return {c.x, c.y, c.z, w.radius[i]};
}

// Body i in the frame, double: the bits of fp64's pack (Real(p − origin), Real(r)).
template <class Real>
CG_HD Sphere<double> local_sphere_fp64(const NarrowBodies<Real>& w, std::uint32_t i) {
  const Vec3<double> c = world_centre(w, i);
  return {c.x - w.origin.x, c.y - w.origin.y, c.z - w.origin.z, w.radius[i]};
}

template <class Real>
struct NarrowDecision {
  bool contact;          // the pair is a contact (d <= ra + rb for spheres: touching counts)
  ContactRow<Real> row;  // world frame; meaningful only when contact
};

// fp32's resolution of a normal: true when the local float centres, each rounded to half an ulp of
// the largest coordinate M of the pair (|error| <= 2^-24 M per coordinate), are far enough apart that
// the normal's angle error, at most sqrt(3)·ε32·M / |d| radians, stays below sqrt(3)·2^-12 rad
// (0.024°): |d| >= 2^12·ε32·M = 2^-11·M. Decided from local coordinates only (rank-independent).
CG_HD bool fp32_resolves(const Sphere<float>& a, const Sphere<float>& b, float len) {
  auto abs_max = [](float u, float v) {
    u = u < 0 ? -u : u;
    v = v < 0 ? -v : v;
    return u > v ? u : v;
  };
  const float m = abs_max(abs_max(abs_max(a.x, a.y), abs_max(a.z, b.x)), abs_max(b.y, b.z));
  return len >= 0x1p-11f * m;
}

// The decision and row of candidate (a, b) for the narrow stage's real type Real (see the file
// comment): fp64 and mixed decide on the frame-local doubles and take the row from the world doubles;
// fp32 decides and computes on the local floats, and takes unresolved normals from the world doubles.
template <class Real>
CG_HD NarrowDecision<Real> narrow_decide(const NarrowBodies<Real>& w, std::uint32_t a, std::uint32_t b,
                                         bool full, NarrowFlags& flags) {
  NarrowDecision<Real> d{};
  if constexpr (std::is_same_v<Real, double>) {
    d.contact = spheres_touch(local_sphere_fp64(w, a), local_sphere_fp64(w, b));
    if (d.contact) d.row = world_sphere_row(world_sphere(w, a), world_sphere(w, b), full);
  } else {
    const Sphere<float> sa = w.spheres[a], sb = w.spheres[b];
    d.contact = spheres_touch(sa, sb);
    if (!d.contact) return d;
    const Vec3<float> dc = sa.centre() - sb.centre();
    if (fp32_resolves(sa, sb, cg_sqrt(dot(dc, dc)))) {
      d.row = sphere_contact_row(sa, sb, w.origin, full);
    } else {
      d.row = row_cast<float>(world_sphere_row(world_sphere(w, a), world_sphere(w, b), full), full);
      ++flags.fp64_rows;
    }
  }
  return d;
}

// How the pair stage filtered its candidates: with the sphere test itself (every candidate is a
// contact), or by the cell rule only (every pair of bodies sharing their first common cell: a looser
// filter, for tests of the rejecting path and for candidate lists kept across calls with a skin).
// bounding_spheres: the sphere test on the bounding spheres of bodies that are not all spheres (scenes
// with ellipsoids), or on the enlarged spheres of mixed's fp32 broad phase (GridParams::radius_margin):
// the same pair-stage filter as spheres_touch, but the narrow stage decides.
enum class CandidateFilter { spheres_touch, cells, bounding_spheres };

// True when narrow_decide() may reject a candidate of this filter: the narrow stage then counts, scans
// and compacts; else it writes one row per candidate (no scan).
CG_HD constexpr bool narrow_may_reject(CandidateFilter f) { return f != CandidateFilter::spheres_touch; }

// True when the pair stage keeps only candidates whose (bounding) spheres touch (spheres_touch()).
CG_HD constexpr bool candidates_touch(CandidateFilter f) { return f != CandidateFilter::cells; }

}  // namespace cg
