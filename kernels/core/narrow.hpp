#pragma once
// The narrow phase's decision, shared by both backends: is a candidate pair a contact, and its row.
// The one place a shape- or precision-specific test slots in: the pair stage only proposes candidates,
// narrow_decide() decides.
//
// Where each precision mode takes its numbers (docs/PRECISION.md):
//   fp64, mixed  decision: spheres_touch on the frame-local doubles Real(world − origin), exactly the
//                bits of fp64's pack, so fp64's pair stage and mixed's narrow stage decide alike
//                (mixed settles most candidates on its broad phase's floats first: touch_fp64);
//                row: from the WORLD doubles (world_sphere_row): the centre difference a − b of two
//                world doubles (exact when they are within a factor 2 of each other, Sterbenz; else
//                one rounding), the points world + offset. No rounding from the frame.
//   fp32         decision and row on the frame-local floats of pack; a pair whose local centres are
//                closer than fp32 resolves (fp32_resolves false) takes the fp64 row from the world
//                doubles, rounded once to float, and is counted (NarrowFlags::fp64_rows).
#include <type_traits>

#include "core/contact.hpp"

namespace cg {

// Flags of one candidate (or summed over a run of candidates), counted into EngineStats: the
// ellipsoid solver's (ellipsoid pairs only), its work, and the fp32 rows recomputed in fp64.
struct NarrowFlags {
  std::uint32_t fallbacks = 0, unconverged = 0, fp64_rows = 0;
  // runs of the general ellipsoid solve (a triage's first start and a hard pair's whole set count
  // one each), the evaluations of f they made (ellipsoid_pair_contact's `iterations`), the most of one
  std::uint32_t solver_runs = 0, evaluations = 0, max_evaluations = 0;
  CG_HD void add(const NarrowFlags& o) {
    fallbacks += o.fallbacks;
    unconverged += o.unconverged;
    fp64_rows += o.fp64_rows;
    solver_runs += o.solver_runs;
    evaluations += o.evaluations;
    max_evaluations = o.max_evaluations > max_evaluations ? o.max_evaluations : max_evaluations;
  }
};

// The bodies as the narrow stage reads them, by body index.
template <class Real>
struct NarrowBodies {
  const Sphere<Real>* spheres;  // fp32: pack's local spheres; fp64 and mixed: not read (may be null)
  const double* position;       // world centres, x y z of body i at 3i (host or DEVICE memory)
  const double* radius;         // world (bounding) radii
  Vec3<double> origin;          // the frame's origin
  // mixed: the fp32 broad phase's spheres (pack's Real(world − origin), radius + broad_margin), by body
  // index, and that margin; null otherwise (touch_fp64).
  const Sphere<float>* broad = nullptr;
  float broad_margin = 0;
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

// What two of mixed's float broad-phase spheres say of fp64's decision (spheres_touch on the
// frame-local doubles). With m = broad_margin = 4·ε32·(L + 2·r_max) (grid_plan.cpp), each packed radius
// is r + m, and the float distance errs by less than 1.74·ε32·L + 7.1·ε32·r_max from the rounded
// centres, the test's arithmetic and the radii's rounding together (docs/PRECISION.md,
// mixed), which is < m. So a float distance <= (r_a + m) + (r_b + m) − 4m puts the exact distance below
// r_a + r_b − m, and one above the sum + 2m puts it beyond r_a + r_b + m; fp64's own rounding is ~2^29
// times smaller than m, so fp64 decides the same. Only a pair within a few m of touching is `unsure`.
enum class BroadSays { apart, touch, unsure };
CG_HD BroadSays broad_says(const Sphere<float>& sa, const Sphere<float>& sb, float m) {
  if (!(m > 0.0f)) return BroadSays::unsure;
  const float dx = sa.x - sb.x, dy = sa.y - sb.y, dz = sa.z - sb.z;
  const float d2 = dx * dx + dy * dy + dz * dz;
  const float sum = sa.r + sb.r;
  const float inner = sum - 4.0f * m, outer = sum + 2.0f * m;
  if (inner > 0.0f && d2 <= inner * inner) return BroadSays::touch;
  if (d2 > outer * outer) return BroadSays::apart;
  return BroadSays::unsure;
}

// fp64's decision, as both fp64 and mixed take it. mixed first reads the two float spheres its broad
// phase tested (16 bytes each, against 32 from two double arrays): only the unsure pairs read the
// world doubles, and the result is fp64's decision bit for bit, with or without the floats.
template <class Real>
CG_HD bool touch_fp64(const NarrowBodies<Real>& w, std::uint32_t a, std::uint32_t b) {
  if (w.broad != nullptr) {
    const BroadSays s = broad_says(w.broad[a], w.broad[b], w.broad_margin);
    if (s != BroadSays::unsure) return s == BroadSays::touch;
  }
  return spheres_touch(local_sphere_fp64(w, a), local_sphere_fp64(w, b));
}

// The pair stage's test of two packed spheres sa, sb (bodies a, b in the stage's own order; `perm`, if
// set, maps it to input order), by candidate filter (below): every pair of the cell rule (CellRule),
// the sphere test itself (SpheresTouch: the default filter, and the bounding or inflated spheres of
// scenes with a skin, mixed with a skin; scenes with ellipsoids: less the centre cut, CentreCut in
// core/centre_cut.hpp), or — mixed, default filter — fp64's decision (Fp64Touch:
// broad_says on the enlarged floats, the world doubles for the unsure pairs), so that mixed's
// candidates are fp64's contacts exactly and its narrow stage writes one row per candidate, as fp64's.
struct CellRule {
  template <class Real>
  CG_HD bool operator()(const Sphere<Real>&, const Sphere<Real>&, std::uint32_t, std::uint32_t) const {
    return true;
  }
};
struct SpheresTouch {
  template <class Real>
  CG_HD bool operator()(const Sphere<Real>& sa, const Sphere<Real>& sb, std::uint32_t, std::uint32_t) const {
    return spheres_touch(sa, sb);
  }
};
// fp64's decision for Fp64Touch's unsure pairs, out of line: rare, and the pair stage's hot loop keeps
// its registers.
CG_HD_OUTLINE bool touch_world(const double* position, const double* radius, Vec3<double> origin,
                               std::uint32_t a, std::uint32_t b) {
  const NarrowBodies<double> w{nullptr, position, radius, origin};
  return spheres_touch(local_sphere_fp64(w, a), local_sphere_fp64(w, b));
}
struct Fp64Touch {
  NarrowBodies<double> world;  // broad unused: the stage passes its floats
  float margin;                // the packed radii's broad_margin
  const std::uint32_t* perm;   // stage order → input order (null: the same)
  CG_HD bool operator()(const Sphere<float>& sa, const Sphere<float>& sb, std::uint32_t a,
                        std::uint32_t b) const {
    const BroadSays s = broad_says(sa, sb, margin);
    if (s != BroadSays::unsure) return s == BroadSays::touch;
    if (perm != nullptr) {
      a = perm[a];
      b = perm[b];
    }
    return touch_world(world.position, world.radius, world.origin, a, b);
  }
};

template <class Real>
struct NarrowDecision {
  bool contact;          // the pair is a contact (d <= ra + rb for spheres: touching counts)
  ContactRow<Real> row;  // world frame; meaningful only when contact
};

// fp32's resolution of a normal: true when the local float centres, each rounded to half an ulp of
// the largest coordinate M of the pair (|error| <= 2^-24 M per coordinate), are far enough apart that
// the normal's angle error, at most sqrt(3)·ε32·M / |d| radians, stays below sqrt(3)·2^-12 rad
// (0.024°): |d| >= 2^12·ε32·M = 2^-11·M. Decided from local coordinates only (rank-independent).
// `fraction`: the threshold as a fraction of M (pairs with an ellipsoid take 2^-16: shape_narrow.hpp).
CG_HD bool fp32_resolves(const Sphere<float>& a, const Sphere<float>& b, float len,
                         float fraction = 0x1p-11f) {
  auto abs_max = [](float u, float v) {
    u = u < 0 ? -u : u;
    v = v < 0 ? -v : v;
    return u > v ? u : v;
  };
  const float m = abs_max(abs_max(abs_max(a.x, a.y), abs_max(a.z, b.x)), abs_max(b.y, b.z));
  return len >= fraction * m;
}

// The decision alone of candidate (a, b) (narrow_decide's `contact`): fp64 and mixed on the
// frame-local doubles, fp32 on the local floats.
template <class Real>
CG_HD bool narrow_touch(const NarrowBodies<Real>& w, std::uint32_t a, std::uint32_t b) {
  if constexpr (std::is_same_v<Real, double>)
    return touch_fp64(w, a, b);
  else
    return spheres_touch(w.spheres[a], w.spheres[b]);
}

// fp32's decision and row of candidate (a, b) from the two local floats sa, sb the caller read (body
// a's and b's: w.spheres by input index, or the CUDA resident steps' cell-ordered copy,
// cuda/cell_order.cuh); unresolved normals from the world doubles of input indices a, b.
template <class Real>
CG_HD NarrowDecision<Real> narrow_decide_floats(const NarrowBodies<Real>& w, const Sphere<float>& sa,
                                                const Sphere<float>& sb, std::uint32_t a, std::uint32_t b,
                                                bool full, NarrowFlags& flags) {
  NarrowDecision<Real> d{};
  d.contact = spheres_touch(sa, sb);  // narrow_touch on the spheres already read
  if (!d.contact) return d;
  const Vec3<float> dc = sa.centre() - sb.centre();
  if (fp32_resolves(sa, sb, cg_sqrt(dot(dc, dc)))) {
    d.row = sphere_contact_row(sa, sb, w.origin, full);
  } else if (w.position == nullptr) {
    // no world doubles (the CUDA host path's 16-byte upload): counted, the row left empty; the call
    // uploads them and runs its narrow stage again (cuda/transfer.cuh: narrow_fp64_rows)
    ++flags.fp64_rows;
  } else {
    d.row = row_cast<float>(world_sphere_row(world_sphere(w, a), world_sphere(w, b), full), full);
    ++flags.fp64_rows;
  }
  return d;
}

// The decision and row of candidate (a, b) for the narrow stage's real type Real (see the file
// comment): fp64 and mixed decide on the frame-local doubles and take the row from the world doubles;
// fp32 decides and computes on the local floats, and takes unresolved normals from the world doubles.
template <class Real>
CG_HD NarrowDecision<Real> narrow_decide(const NarrowBodies<Real>& w, std::uint32_t a, std::uint32_t b,
                                         bool full, NarrowFlags& flags) {
  NarrowDecision<Real> d{};
  if constexpr (std::is_same_v<Real, double>) {
    d.contact = narrow_touch(w, a, b);
    if (d.contact) d.row = world_sphere_row(world_sphere(w, a), world_sphere(w, b), full);
  } else {
    d = narrow_decide_floats(w, w.spheres[a], w.spheres[b], a, b, full, flags);
  }
  return d;
}

// How the pair stage filtered its candidates: with the sphere test itself (every candidate is a
// contact), or by the cell rule only (every pair of bodies sharing their first common cell: a looser
// filter, for tests of the rejecting path and for candidate lists kept across calls with a skin).
// bounding_spheres: the sphere test on the bounding spheres of bodies that are not all spheres (scenes
// with ellipsoids), or on the enlarged spheres of mixed's fp32 broad phase (GridParams::radius_margin):
// the same pair-stage filter as spheres_touch, but the narrow stage decides.
// centre_cut: bounding_spheres less the general ellipsoid pairs that the centre line proves apart
// (core/centre_cut.hpp): the default where at least 4 bodies in 5 are ellipsoids and there is no skin
// (scene_filter); the same contacts.
enum class CandidateFilter { spheres_touch, cells, bounding_spheres, centre_cut };

// True when narrow_decide() may reject a candidate of this filter: the narrow stage then counts, scans
// and compacts; else it writes one row per candidate (no scan).
CG_HD constexpr bool narrow_may_reject(CandidateFilter f) { return f != CandidateFilter::spheres_touch; }

// True when the pair stage keeps only candidates whose (bounding) spheres touch (spheres_touch()).
CG_HD constexpr bool candidates_touch(CandidateFilter f) { return f != CandidateFilter::cells; }

// The filter a call runs (both backends, from the same counts, so the same candidates): the requested
// one (spheres_touch unless a test or knob forces another) made fit for the scene — with ellipsoids, the
// bounding spheres, less the centre cut (core/centre_cut.hpp) where at least 4 bodies in 5 are
// ellipsoids: it cuts pairs of two general ellipsoids alone, and its shapes cost every body a gather into
// cell order, more than half-sphere scenes gain (BENCHMARKS.md §3). With a skin the (inflated) bounding
// spheres, whose list must outlast the bodies' motion: in the same scenes less the centre cut with the
// skin as its margin (core/centre_cut.hpp: its check then counts rotations), unless `skin_cut` is
// false (CONTACTGRID_SKIN_CUT=0, core/skin.hpp: skin_cut_enabled), the bounding spheres alone.
CG_HD constexpr CandidateFilter scene_filter(CandidateFilter requested, std::uint64_t ellipsoids,
                                             std::uint64_t bodies, bool skin, bool skin_cut) {
  if (requested != CandidateFilter::spheres_touch || !(ellipsoids > 0 || skin)) return requested;
  return (!skin || skin_cut) && 5 * ellipsoids >= 4 * bodies ? CandidateFilter::centre_cut
                                                             : CandidateFilter::bounding_spheres;
}

}  // namespace cg
