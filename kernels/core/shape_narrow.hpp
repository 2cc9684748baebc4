#pragma once
// The narrow phase's deciders for the rejecting path (count → scan → fill), shared by the CPU backend
// (host/narrow.cpp) and the CUDA kernels (cuda/narrow.cuh, cuda/narrow_shapes.cuh): the same struct, the same
// CG_HD calls in the same order, so both backends decide and write the same bits.
//   accept(a, b, flags)  the count pass: is candidate (a, b) a contact (and the solver's flags, counted
//                        once per candidate into EngineStats)
//   row(a, b, full)      the fill pass, for an accepted candidate: its row, world frame
//   ShapeDecide only: triage (screen + first_pass) / settle / solve / row_from, the three-pass count
//   both backends run (below); its accept / row are the one whole solve per candidate that the passes
//   must reproduce bit for bit
//   (EngineShapesTest.ThreePassNarrowEqualsOneWholeSolve), and row serves the closed-form pairs.
// The bodies come as NarrowBodies (core/narrow.hpp): fp64 and mixed decide and compute from the world
// doubles (pair_frame), fp32 from pack's local floats — except the pairs whose float centres it does
// not resolve, which it solves as fp64 does (ShapeDecide, "fp32's pairs in fp64").
// SphereDecide: narrow_decide() on the bounding spheres (sphere-only scenes, looser filters).
// ShapeDecide: scenes with ellipsoids: dispatch on the shape pair —
//   sphere–sphere        the closed form (narrow_decide: exactly the sphere path's bits)
//   sphere–ellipsoid     sphere_ellipsoid_contact (the sphere's `radius` is its radius)
//   ellipsoid–ellipsoid  ellipsoid_contact (Perram–Wertheim filter, then the solve)
// Contact iff distance <= 0 (docs/FORMAT.md §3). Local points of an ellipsoid are in its body frame,
// R_Xᵀ(p − x); of a sphere p − x. Both backends split the count pass in two (triage, then solve for
// the hard pairs alone) and keep each general ellipsoid pair's minimiser, from which the row is
// rebuilt (row_from()): the host at once, the device in its fill pass.
#include <cstdint>
#include <type_traits>

#include "core/ellipsoid_contact.hpp"
#include "core/narrow.hpp"
#include "core/shape.hpp"

namespace cg {

template <class Real>
struct SphereDecide {
  NarrowBodies<Real> bodies;
  CG_HD bool accept(std::uint32_t a, std::uint32_t b, NarrowFlags& flags) const {
    return narrow_decide(bodies, a, b, false, flags).contact;
  }
  // The decision alone (no row, no flags): the CUDA one-pass compaction's select, whose row and flags
  // come from row_flags() for the accepted pairs alone.
  CG_HD bool touch(std::uint32_t a, std::uint32_t b) const { return narrow_touch(bodies, a, b); }
  CG_HD ContactRow<Real> row_flags(std::uint32_t a, std::uint32_t b, bool full, NarrowFlags& flags) const {
    return narrow_decide(bodies, a, b, full, flags).row;
  }
  CG_HD ContactRow<Real> row(std::uint32_t a, std::uint32_t b, bool full) const {
    NarrowFlags unused;  // counted by accept()
    return narrow_decide(bodies, a, b, full, unused).row;
  }
  template <bool = true>
  CG_HD ContactRow<Real> row_from(std::uint32_t a, std::uint32_t b, Vec3<Real>, bool full) const {
    return row(a, b, full);  // nothing kept: the closed form again
  }
};

// The ellipsoid of body i: the centre of its bounding sphere, packed semi-axes, the rotation of its
// packed orientation.
template <class Real>
CG_HD Ellipsoid<Real> ellipsoid_of(const Sphere<Real>& s, const PackedShape<Real>& p) {
  return {s.centre(), p.semi_axes, rotation_matrix(p.orientation)};
}

// The contact of a pair with at least one ellipsoid (in the frame of sa, sb) and whether it is one.
// `carry`: ellipsoid_contact's (a general pair's first start, kept or resumed).
template <SolveScope Scope = SolveScope::whole, class Real, class Runs = SerialRuns>
CG_HD bool shape_pair_contact(const Sphere<Real>& sa, const Sphere<Real>& sb, const PackedShape<Real>& pa,
                              const PackedShape<Real>& pb, const SolverSettings<Real>& settings,
                              EllipsoidContact<Real>& c, const Runs& runs = {},
                              FirstStart<Real>* carry = nullptr) {
  constexpr std::uint32_t sphere = static_cast<std::uint32_t>(Shape::sphere);
  if (pa.kind == sphere) {
    c = sphere_ellipsoid_contact(sa, ellipsoid_of(sb, pb), true);
    return c.geometry.distance <= Real(0);
  }
  if (pb.kind == sphere) {
    c = sphere_ellipsoid_contact(sb, ellipsoid_of(sa, pa), false);
    return c.geometry.distance <= Real(0);
  }
  const EllipsoidPairResult<Real> r =
      ellipsoid_contact<Scope>(ellipsoid_of(sa, pa), ellipsoid_of(sb, pb), settings, runs, carry);
  c = r.contact;
  return r.in_contact;
}

// The two bounding spheres of a pair in the frame the solve runs in, and that frame's origin (world).
// fp64 and mixed: B's world centre, so A's centre is the world difference a − b (exact when they are
// within a factor 2 of each other) and B's is 0: the solve sees the exact centre difference, and its
// points come back as b + offset. fp32: the engine's frame (pack's local floats).
template <class Real>
struct PairFrame {
  Sphere<Real> a, b;
  Vec3<double> origin;
};
template <class Real>
CG_HD PairFrame<double> world_pair_frame(const NarrowBodies<Real>& w, std::uint32_t a, std::uint32_t b) {
  const Sphere<double> wa = world_sphere(w, a), wb = world_sphere(w, b);
  return {{wa.x - wb.x, wa.y - wb.y, wa.z - wb.z, wa.r}, {0, 0, 0, wb.r}, wb.centre()};
}
template <class Real>
CG_HD PairFrame<Real> pair_frame(const NarrowBodies<Real>& w, std::uint32_t a, std::uint32_t b) {
  if constexpr (std::is_same_v<Real, double>)
    return world_pair_frame(w, a, b);
  else
    return {w.spheres[a], w.spheres[b], w.origin};
}

// The solver settings of fp32's fp64 solves: fp64's tolerance (its default: the pair is solved in
// double for fp64's answer, which fp32's 2e-5 would leave a million times coarser; a tolerance the
// user sets applies to the float solves), the start set and caps of the engine's settings.
template <class Real>
CG_HD SolverSettings<double> fp64_settings(const SolverSettings<Real>& s) {
  SolverSettings<double> d;
  d.max_iterations = s.max_iterations;
  d.starts = s.starts;
  d.screen = s.screen;
  d.certify = s.certify;
  return d;
}

// A pair with an ellipsoid is decided only when its bounding spheres touch, as narrow_decide decides
// a sphere pair (fp64 and mixed: the frame-local doubles; fp32: the packed floats): a looser
// candidate list (the cell rule, mixed's enlarged spheres, a list kept with a skin) then gives the
// same contacts and solver flags as the bounding spheres themselves, also for a pair whose solve
// would call it touching within the solver's tolerance while its bounding spheres do not quite.
template <class Real>
CG_HD bool bounding_spheres_touch(const NarrowBodies<Real>& w, std::uint32_t a, std::uint32_t b) {
  if constexpr (std::is_same_v<Real, double>)
    return touch_fp64(w, a, b);
  else
    return spheres_touch(w.spheres[a], w.spheres[b]);
}

// fp32's pairs in fp64: a pair with an ellipsoid whose local float centres are closer than 2^-16·M
// (fp32_resolves, core/narrow.hpp, M the largest |local coordinate| of the pair) is decided and solved
// in double as fp64 solves it — fp64's pair frame from the world centres (A's centre a − b, B's 0,
// points back as b + offset) and fp64's packed shapes, rebuilt from the world shape rows
// (pack_shape<double>, not the float rows promoted: a rotation rounded to float is orthonormal only to
// 2^-24, and semi-axes equal in float may differ in double, so the promoted rows would be neither
// fp32's bodies nor fp64's) — and its row is fp64's row rounded to float once (row_cast), counted in
// NarrowFlags::fp64_rows. Why 2^-16 (the sphere pairs take 2^-11, where the normal IS the direction of
// a − b): the rounded a − b errs by δ ≤ √3·ε32·M, which perturbs f(n) = h_A(−n) + h_B(n) − n·(a − b)
// by at most |δ| whatever |a − b| (so the minimiser's shift within its basin does not depend on the
// threshold), and chooses between the mirror minima ±n (f(−n) − f(n) = 2 n·(a − b)) only where
// |n·(a − b)| ≤ |δ|. Below the threshold the rounded difference may point anywhere (or be 0), so the
// float solve may take the mirror normal; above it, the direction of
// a − b is right to √3·2^-8 rad, so a mirror is taken only where n is within that of perpendicular
// to a − b — a pair with two exits deeper than each other by less than fp32's band, either normal
// right. (A larger threshold such as 2^-11 sends many more pairs of a random scene to serial double
// solves, at a large cost on the GPU: BENCHMARKS.md §3.) Every entry
// point agrees: accept / row solve it so, triage sends it to the hard pass (Verdict::hard: the triage
// kernel stays lean), solve solves it so, row_from solves it again (the kept float normal is not the
// double minimiser): one-solve bits. The device runs those solves in kernels of their own
// (cuda/narrow_shapes.cuh: kFp64Pairs false keeps the double code out of the hard and fill kernels).
template <class Real>
struct ShapeDecide {
  NarrowBodies<Real> bodies;
  const PackedShape<Real>* shapes;  // by body index
  SolverSettings<Real> settings;
  ShapeRowsView rows;  // fp32: the world shape rows (fp64 and mixed: not read)
  // The pair stage took the centre cut (CandidateFilter::centre_cut, core/centre_cut.hpp): the pairs
  // apart along the centre line by more than the cut's margin are gone, so the screen leaves the test to
  // the first pass's ellipsoid_contact (which starts with it: the same verdict, no solver work) instead
  // of taking it for every general pair, which the cut leaves few to reject (BENCHMARKS.md §3).
  bool centre_cut = false;

  CG_HD bool both_spheres(std::uint32_t a, std::uint32_t b) const {
    return shapes[a].kind == static_cast<std::uint32_t>(Shape::sphere) &&
           shapes[b].kind == static_cast<std::uint32_t>(Shape::sphere);
  }
  // fp32 only: pair (a, b) (with an ellipsoid) is solved in fp64 (above).
  CG_HD bool in_fp64(std::uint32_t a, std::uint32_t b) const {
    if constexpr (std::is_same_v<Real, float>) {
      const Sphere<float> sa = bodies.spheres[a], sb = bodies.spheres[b];
      const Vec3<float> dc = sa.centre() - sb.centre();
      return !fp32_resolves(sa, sb, cg_sqrt(dot(dc, dc)), 0x1p-16f);
    } else {
      return false;
    }
  }
  CG_HD bool accept(std::uint32_t a, std::uint32_t b, NarrowFlags& flags) const {
    if (both_spheres(a, b)) return narrow_decide(bodies, a, b, false, flags).contact;
    if (!bounding_spheres_touch(bodies, a, b)) return false;  // (above)
    if (in_fp64(a, b)) return fp64_solve(a, b, flags).contact;
    EllipsoidContact<Real> c;
    const PairFrame<Real> f = pair_frame(bodies, a, b);
    const bool contact = shape_pair_contact(f.a, f.b, shapes[a], shapes[b], settings, c);
    note(a, b, c, flags);
    return contact;
  }
  // kFp64Pairs false (the device's lean kernels): the caller has taken fp32's pairs in fp64 elsewhere
  // (cuda/narrow_shapes.cuh), so the double solve's code is not in the kernel (row, solve, row_from).
  template <bool kFp64Pairs = true, SolveScope Scope = SolveScope::whole>
  CG_HD ContactRow<Real> row(std::uint32_t a, std::uint32_t b, bool full) const {
    NarrowFlags unused;  // counted by accept()
    if (both_spheres(a, b)) return narrow_decide(bodies, a, b, full, unused).row;
    if constexpr (kFp64Pairs)
      if (in_fp64(a, b)) return fp64_row(a, b, full);
    EllipsoidContact<Real> c;
    const PairFrame<Real> f = pair_frame(bodies, a, b);
    shape_pair_contact<Scope>(f.a, f.b, shapes[a], shapes[b], settings, c);
    return row_of(c, f.origin, full);
  }
  // The three-pass narrow of both backends (host/narrow_shapes.cpp, cuda/narrow_shapes.cuh): triage settles
  // each candidate cheaply — screen(): closed forms, the sphere–ellipsoid root find, the centre line;
  // then for the general pairs it leaves (Verdict::solve; on the device a list of their own, so that
  // the Newton runs fill whole warps) first_pass(): the PW filter and the first start with the cheap
  // certificates — and keeps the minimiser `n` of a general ellipsoid pair; the rest (Verdict::hard, and
  // fp32's pairs in fp64) go to settle(), the first start again with every certificate (the inner ellipsoid
  // settles nearly all deep overlaps), over those candidates alone; what is still hard takes solve(), the
  // whole start set; row_from() rebuilds the row from the kept minimiser (contact_at_normal: the bits of
  // row(), without solving again; fp32's pairs in fp64 are solved again). Each pass counts the work it does,
  // on both backends alike.
  enum class Verdict : std::uint32_t { reject = 0, accept = 1, hard = 2, solve = 3 };
  // `carry` (FirstStart, optional): first_pass keeps a hard pair's first start there, settle goes on
  // from it (the same bits and counts as running it again: ellipsoid_solve.hpp).
  template <SolveScope Scope>
  CG_HD Verdict first_start(std::uint32_t a, std::uint32_t b, NarrowFlags& flags, Vec3<Real>& n,
                            FirstStart<Real>* carry = nullptr) const {
    EllipsoidContact<Real> c;
    const PairFrame<Real> f = pair_frame(bodies, a, b);
    const bool contact =
        shape_pair_contact<Scope>(f.a, f.b, shapes[a], shapes[b], settings, c, SerialRuns{}, carry);
    if (!c.complete) {
      note_work(a, b, c, flags);
      return Verdict::hard;
    }
    note(a, b, c, flags);
    n = c.geometry.normal_on_b;
    return contact ? Verdict::accept : Verdict::reject;
  }
  CG_HD Verdict screen(std::uint32_t a, std::uint32_t b, NarrowFlags& flags, Vec3<Real>& n) const {
    if (both_spheres(a, b))
      return narrow_decide(bodies, a, b, false, flags).contact ? Verdict::accept : Verdict::reject;
    if (!bounding_spheres_touch(bodies, a, b)) return Verdict::reject;  // (above)
    if (in_fp64(a, b)) return Verdict::hard;
    if (!general_pair(a, b)) return first_start<SolveScope::none>(a, b, flags, n);  // (complete)
    if (centre_cut) return Verdict::solve;                                          // (above)
    const PairFrame<Real> f = pair_frame(bodies, a, b);
    if (separated_along_centres(ellipsoid_of(f.a, shapes[a]), ellipsoid_of(f.b, shapes[b])))
      return Verdict::reject;
    return Verdict::solve;
  }
  CG_HD Verdict first_pass(std::uint32_t a, std::uint32_t b, NarrowFlags& flags, Vec3<Real>& n,
                           FirstStart<Real>* carry = nullptr) const {
    return first_start<SolveScope::first_start_cheap>(a, b, flags, n, carry);
  }
  CG_HD Verdict triage(std::uint32_t a, std::uint32_t b, NarrowFlags& flags, Vec3<Real>& n,
                       FirstStart<Real>* carry = nullptr) const {
    const Verdict v = screen(a, b, flags, n);
    return v == Verdict::solve ? first_pass(a, b, flags, n, carry) : v;
  }
  // A candidate triage left hard; `carry`: what its first pass kept (null: both run again; a pair the
  // screen left hard, fp32's pair in fp64, has none and needs none).
  CG_HD Verdict settle(std::uint32_t a, std::uint32_t b, NarrowFlags& flags, Vec3<Real>& n,
                       FirstStart<Real>* carry = nullptr) const {
    if (in_fp64(a, b)) return Verdict::hard;
    return first_start<SolveScope::first_start>(a, b, flags, n, carry);
  }
  // `runs`: how the start set's runs go (SerialRuns; the device's warp kernel: WarpRuns, the same bits).
  template <bool kFp64Pairs = true, class Runs = SerialRuns>
  CG_HD bool solve(std::uint32_t a, std::uint32_t b, NarrowFlags& flags, Vec3<Real>& n,
                   const Runs& runs = {}) const {
    if constexpr (kFp64Pairs) {
      if (in_fp64(a, b)) {
        const Fp64Pair p = fp64_solve(a, b, flags);
        n = vec_cast<Real>(p.c.geometry.normal_on_b);  // not read back (row_from solves again)
        return p.contact;
      }
    }
    EllipsoidContact<Real> c;
    const PairFrame<Real> f = pair_frame(bodies, a, b);
    const bool contact = shape_pair_contact(f.a, f.b, shapes[a], shapes[b], settings, c, runs);
    note(a, b, c, flags);
    n = c.geometry.normal_on_b;
    return contact;
  }
  // The solver's flags of a settled pair, and its work (general pairs that reached the solve: the PW
  // filter's rejections and the closed forms make none).
  // (R: Real, or double for fp32's pairs in fp64)
  template <class R>
  CG_HD void note(std::uint32_t a, std::uint32_t b, const EllipsoidContact<R>& c, NarrowFlags& flags) const {
    flags.fallbacks += c.fallback ? 1u : 0u;
    flags.unconverged += c.converged ? 0u : 1u;
    note_work(a, b, c, flags);
  }
  template <class R>
  CG_HD void note_work(std::uint32_t a, std::uint32_t b, const EllipsoidContact<R>& c,
                       NarrowFlags& flags) const {
    if (c.iterations <= 0 || !general_pair(a, b)) return;
    const auto e = static_cast<std::uint32_t>(c.iterations);
    ++flags.solver_runs;
    flags.evaluations += e;
    flags.max_evaluations = e > flags.max_evaluations ? e : flags.max_evaluations;
  }
  // A pair of ellipsoids that takes the general solve (ellipsoid_contact: neither has equal axes).
  CG_HD bool general_pair(std::uint32_t a, std::uint32_t b) const {
    auto general = [](const PackedShape<Real>& p) {
      const Vec3<Real> e = p.semi_axes;
      return p.kind == static_cast<std::uint32_t>(Shape::ellipsoid) && !(e.x == e.y && e.y == e.z);
    };
    return general(shapes[a]) && general(shapes[b]);
  }
  template <bool kFp64Pairs = true>
  CG_HD ContactRow<Real> row_from(std::uint32_t a, std::uint32_t b, Vec3<Real> n, bool full) const {
    // closed forms and root finds: cheap again (and no general solve's code: SolveScope::none)
    if (!general_pair(a, b)) return row<kFp64Pairs, SolveScope::none>(a, b, full);
    if constexpr (kFp64Pairs)
      if (in_fp64(a, b)) return fp64_row(a, b, full);
    EllipsoidContact<Real> c{};
    const PairFrame<Real> f = pair_frame(bodies, a, b);
    contact_at_normal(ellipsoid_of(f.a, shapes[a]), ellipsoid_of(f.b, shapes[b]), n, c);
    return row_of(c, f.origin, full);
  }
  CG_HD static ContactRow<Real> row_of(const EllipsoidContact<Real>& c, const Vec3<double>& origin,
                                       bool full) {
    ContactRow<Real> row{};
    row.position_on_a = to_world(origin, c.geometry.position_on_a);
    row.position_on_b = to_world(origin, c.geometry.position_on_b);
    row.normal_on_b = c.geometry.normal_on_b;
    row.distance = c.geometry.distance;
    if (full) {
      row.local_point_a = c.local_point_a;
      row.local_point_b = c.local_point_b;
      plane_space(c.geometry.normal_on_b, row.lateral_friction_dir1, row.lateral_friction_dir2);
    }
    return row;
  }

  // ---- fp32's pairs in fp64 (above); out of line on the device, so that the kernels' common path
  // keeps its registers (only the hard and fill kernels reach it) ----
  struct Fp64Pair {
    EllipsoidContact<double> c;
    Vec3<double> origin;  // B's world centre: the frame's origin
    bool contact;
  };
  // fp64's packed shape of body i, from the world shape rows.
  CG_HD PackedShape<double> fp64_shape(std::uint32_t i) const {
    return pack_shape<double>(static_cast<std::uint8_t>(shapes[i].kind), rows.semi_axes + 3 * std::size_t(i),
                              rows.orientation + 4 * std::size_t(i));
  }
  // The whole solve of pair (a, b) in double, as fp64's ShapeDecide::accept / row run it.
  CG_HD_OUTLINE Fp64Pair fp64_pair(std::uint32_t a, std::uint32_t b) const {
    Fp64Pair p;
    const PairFrame<double> f = world_pair_frame(bodies, a, b);
    p.origin = f.origin;
    p.contact = shape_pair_contact(f.a, f.b, fp64_shape(a), fp64_shape(b), fp64_settings(settings), p.c);
    return p;
  }
  // The count pass's solve: the solver's flags, and the row counted as an fp64 row.
  CG_HD Fp64Pair fp64_solve(std::uint32_t a, std::uint32_t b, NarrowFlags& flags) const {
    const Fp64Pair p = fp64_pair(a, b);
    note(a, b, p.c, flags);
    flags.fp64_rows += p.contact ? 1u : 0u;
    return p;
  }
  // fp64's row, rounded to Real once.
  CG_HD_OUTLINE ContactRow<Real> fp64_row(std::uint32_t a, std::uint32_t b, bool full) const {
    const Fp64Pair p = fp64_pair(a, b);
    return row_cast<Real>(ShapeDecide<double>::row_of(p.c, p.origin, full), full);
  }
};

}  // namespace cg
