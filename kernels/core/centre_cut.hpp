#pragma once
// The centre cut: the pair stage's shape test for scenes of ellipsoids (CandidateFilter::centre_cut: at
// least 4 bodies in 5, core/narrow.hpp's scene_filter), shared by both backends. In a random scene of
// semi-axes U[0.25, 1] about 56 % of the bounding-sphere candidates are apart, and the centre line alone
// proves 48 % of them apart (two support values: separated_along_centres, core/ellipsoid_contact.hpp). Taken
// in the pair stage, where both bodies are in cell order, it halves the candidates that the order stage sorts
// and the narrow stage screens at random places in id order. Its price is the cut shapes in cell order,
// which a reorder would gather at random: so these scenes with float spheres keep their input order
// (cuda/pack.cuh; the figures: BENCHMARKS.md §3, "the centre cut").
//
// It removes only pairs the narrow stage rejects anyway, so the contacts, their bits and the solver's
// flags are the same with or without it: it cuts general ellipsoid pairs alone (the ones whose narrow
// path starts with separated_along_centres: the screen, or fp32's pairs in fp64 through
// ellipsoid_contact), and only when the gap it finds exceeds the screen's own gap by more than the
// difference of the two evaluations can be:
//   - the broad phase's centres (pack's local Broad) against the narrow's (the same floats for fp32;
//     fp64 and mixed: the world difference of the doubles, correctly rounded), each coordinate off by
//     at most ε_Broad·|c|: |δ| ≤ ε_Broad·(|a|₁ + |b|₁); the length moves by |δ|, the direction by
//     2|δ|/len, so each support value by its largest semi-axis times that (h is Lipschitz with it);
//   - the support values of R D² Rᵀ in float (here) and of the rotation the narrow builds (in Narrow,
//     or fp32's pairs in fp64 from the double rows): relative errors of a few ε32 at most.
// So the cut asks gap > 2^-10·(ra + rb + len) + 4·ε_Broad·(|a|₁ + |b|₁)·(1 + (ra + rb)/len), with ra, rb
// the pair stage's (bounding) radii ≥ the largest semi-axes: a thousand times the rounding terms, and
// still nearly every apart pair it could cut (the gap of a pair apart along the centre line is rarely
// that thin). The narrow's rejections are thus unchanged, pair by pair
// (tests: CentreCut.*, EngineShapesTest.CentreCutGivesTheSameRows, the device's CudaBitIdenticalToCpu).
//
// The cut shapes also give each body its cells: the box of its shape instead of its bounding sphere's
// (cut_cells, below): fewer entries a body and fewer pair tests, the same contacts (BENCHMARKS.md §3, "the
// cells of the shapes' boxes").
//
// Spheres, ellipsoids with three equal semi-axes (the sphere–ellipsoid path, which has no centre-line
// test), and sphere pairs are never cut: their CutShape is NaN, and a NaN gap is no gap.
//
// A skin (EngineOptions::skin s, core/skin.hpp; CONTACTGRID_SKIN_CUT=0 keeps the bounding spheres
// alone): a build cuts with the skin as the cut's margin (CentreCut::skin = 2·inflation >= s), and the
// check counts rotations. Why the list then still holds every contact:
//   - the centre-line gap g = len − h_a(u) − h_b(u) (u the unit centre line, h the support function)
//     bounds the distance of the two bodies from below: they lie in the slabs u·x <= u·a + h_a(u) and
//     u·x >= u·b − h_b(u), g apart, and a projection is 1-Lipschitz;
//   - a body whose every point moves by at most m_i changes every distance to it by at most m_i. A rigid
//     motion with centre translation t_i and rotation q q0⁻¹ of angle θ_i about the centre moves a point
//     at distance <= ρ_i from it (ρ_i the bounding radius, the largest semi-axis) by at most
//     m_i = t_i + 2ρ_i·sin(θ_i/2), and sin(θ_i/2) = |vector part of q q0⁻¹| for unit quaternions
//     (turned_motion, below; the check's maximum of it is the motion, Motion::displacement);
//   - so a pair the build cuts (gap > s + the cut's margin) is, at a later call whose check passed
//     (2·max m_i <= s, semi-axes and kinds unchanged: Motion::shape_changed), apart by more than the
//     cut's margin — 2^-10 of the (inflated, so larger) radii and the length, and the coordinate
//     term widened by 8s, which covers the move of both bodies and of the frame's origin (the bounds'
//     low corner, <= s/2 per axis each: |δ|₁ <= 3s a body). Apart by that much the narrow rejects the
//     pair (as two bodies of disjoint cut boxes, cut_box below: the centre line, PW's F >= (1 + 2^-10)²
//     before any solve, or a converged solve of a separated pair): the rows of every reuse are a fresh
//     detection's, bit for bit (tests: EngineSkinTest.*Cut*).
// The float skin's rounding (relative ε32) and the double motion's (a few ε64) are far inside the 2^-10
// term. The cells of a skin's build stay those of the inflated bounding spheres (cut_box depends on
// the orientation; the pair stage's sphere test of the inflated radii covers the translation).
#include <cstdint>
#include <limits>

#include "core/contact.hpp"
#include "core/grid.hpp"
#include "core/narrow.hpp"
#include "core/quat.hpp"
#include "core/shape.hpp"

namespace cg {

// R D² Rᵀ of an ellipsoid in float (h(u)² = uᵀ C u), by the pair stage's body order: 24 bytes a body in
// every precision mode — the cut's own rounding is far inside its margin (above). NaN for the bodies
// the cut leaves alone.
struct CutShape {
  float xx, yy, zz, xy, xz, yz;
};

template <class Packed>
CG_HD CutShape cut_shape(const PackedShape<Packed>& p) {
  const Vec3<Packed> e = p.semi_axes;
  if (p.kind != static_cast<std::uint32_t>(Shape::ellipsoid) || (e.x == e.y && e.y == e.z)) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    return {nan, nan, nan, nan, nan, nan};
  }
  const Mat3<Packed> r = rotation_matrix(p.orientation);
  const Vec3<Packed> d2{e.x * e.x, e.y * e.y, e.z * e.z};
  auto c = [&](const Vec3<Packed>& u, const Vec3<Packed>& v) {
    return static_cast<float>(u.x * d2.x * v.x + u.y * d2.y * v.y + u.z * d2.z * v.z);
  };
  return {c(r.r0, r.r0), c(r.r1, r.r1), c(r.r2, r.r2), c(r.r0, r.r1), c(r.r0, r.r2), c(r.r1, r.r2)};
}

CG_HD float cut_support(const CutShape& c, float x, float y, float z) {
  return cg_sqrt(x * (c.xx * x + c.xy * y + c.xz * z) + y * (c.xy * x + c.yy * y + c.yz * z) +
                 z * (c.xz * x + c.yz * y + c.zz * z));
}

// True when the centre line proves the pair apart with the margin above (false for NaN shapes). The
// centre difference is taken in Real (the broad phase's own), then the cut runs in float: its rounding
// (relative, a few ε32) is covered by the 2^-10 term; the coordinate term is of the broad phase's
// rounding, ε_Real.
// `skin`: a skin's build (above): the gap must also exceed the skin, the coordinate term covers 8·skin
// more (0: a fresh call's cut, the same arithmetic as without it).
template <class Real>
CG_HD bool cut_apart(const Sphere<Real>& sa, const Sphere<Real>& sb, const CutShape& ca, const CutShape& cb,
                     float skin = 0.0f) {
  const float x = static_cast<float>(sa.x - sb.x), y = static_cast<float>(sa.y - sb.y),
              z = static_cast<float>(sa.z - sb.z);
  const float len2 = x * x + y * y + z * z;
  if (!(len2 > 0.0f)) return false;
  const float len = cg_sqrt(len2), inv = 1.0f / len;
  const float ux = x * inv, uy = y * inv, uz = z * inv;
  const float gap = len - (cut_support(ca, ux, uy, uz) + cut_support(cb, ux, uy, uz));
  if (!(gap > 0.0f)) return false;  // (NaN: not cut)
  auto l1 = [](const Sphere<Real>& s) {
    return (s.x < 0 ? -s.x : s.x) + (s.y < 0 ? -s.y : s.y) + (s.z < 0 ? -s.z : s.z);
  };
  const float size = static_cast<float>(sa.r + sb.r);
  const float coords = static_cast<float>(Real(4) * std::numeric_limits<Real>::epsilon() *
                                          (l1(sa) + l1(sb) + Real(8) * static_cast<Real>(skin)));
  return gap > skin + (0x1p-10f * (size + len) + coords * (1.0f + size / len));
}

// A body's motion bound of the check of a skin's cut list (above): its centre moved by (dx, dy, dz)
// and it turned from orientation q0 to q (w, x, y, z; any norm: sin(θ/2) = |v(q q0*)| / (|q| |q0|)),
// `radius` its bounding radius: every point of it moved by at most the result. In double, the same
// operations on both backends.
CG_HD double turned_motion(double dx, double dy, double dz, double radius, const double* q,
                           const double* q0) {
  // the vector part of q q0*: w0·v − w·v0 − v × v0
  const double vx = q0[0] * q[1] - q[0] * q0[1] - (q[2] * q0[3] - q[3] * q0[2]);
  const double vy = q0[0] * q[2] - q[0] * q0[2] - (q[3] * q0[1] - q[1] * q0[3]);
  const double vz = q0[0] * q[3] - q[0] * q0[3] - (q[1] * q0[2] - q[2] * q0[1]);
  const double n2 = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) *
                    (q0[0] * q0[0] + q0[1] * q0[1] + q0[2] * q0[2] + q0[3] * q0[3]);
  double s2 = (vx * vx + vy * vy + vz * vz) / n2;
  if (!(s2 <= 1.0)) s2 = 1.0;  // (rounding, or a NaN: the largest turn)
  return cg_sqrt(dx * dx + dy * dy + dz * dz) + 2.0 * radius * cg_sqrt(s2);
}

// The cells of a body in the scenes of the centre cut: the box of its shape, not of its bounding sphere.
// Along axis k an ellipsoid reaches h(e_k) = √C_kk from its centre (C = R D² Rᵀ, its cut shape), on
// average 0.64 against a bounding radius of 0.81 for semi-axes U[0.25, 1]: 2.12 instead of 2.53 entries
// a body, and fewer bodies in each cell to test. Widened by the cut's margin — 2^-10 of the bounding
// radius for the rounding of C and of the narrow's rotation (relative, a few ε32), and the broad
// phase's coordinate rounding 4·ε_Real·|c|₁ (mixed: + its enlargement) — and never beyond the bounding
// radius (spheres and bodies the cut leaves: NaN, the bounding radius). Two bodies whose boxes share no
// cell are apart along an axis by more than the margins (cell_coord is monotone), so the narrow rejects
// them: the centre line or PW before any solve (F ≥ (1 + 2^-10)², far outside PW's band up to aspect
// 1:16), beyond it a converged solve of a separated pair (convex there). The same contacts, bit for
// bit (EngineShapesTest.CentreCutGivesTheSameRows); fewer pair tests.
// (cut_box: the half-extents of the box; `enlarge` is mixed's radius margin, else 0.)
template <class Real>
CG_HD Vec3<Real> cut_box(const Sphere<Real>& s, const CutShape& c, Real enlarge) {
  auto abs = [](Real v) { return v < Real(0) ? -v : v; };
  const Real margin = Real(0x1p-10) * s.r +
                      Real(4) * std::numeric_limits<Real>::epsilon() * (abs(s.x) + abs(s.y) + abs(s.z)) +
                      enlarge;
  auto half = [&](float ckk) {
    const Real e = static_cast<Real>(cg_sqrt(ckk)) + margin;
    return e < s.r ? e : s.r;  // (NaN: the bounding radius)
  };
  return {half(c.xx), half(c.yy), half(c.zz)};
}
template <class Real>
CG_HD BodyCells cut_cells(const Sphere<Real>& s, const CutShape& c, const GridParams<Real>& g) {
  const Vec3<Real> e = cut_box(s, c, g.radius_margin);
  return box_cells(s, e.x, e.y, e.z, g);
}

// The pair stage's test for CandidateFilter::centre_cut (core/narrow.hpp's tests: the spheres of bodies
// a, b in the stage's own order, `cut` in the same order): the bounding spheres touch (Coarse) and the
// centre line does not prove the shapes apart (refine). The device's pair walk takes the two apart —
// the coarse test in its hot loop, refine over the pairs it found after it (cuda/pairs.cuh): inside
// the loop the cut's registers would slow every test (BENCHMARKS.md §3).
// `skin`: a skin's build (its spheres inflated): 2·inflation, 0 for a fresh call (cut_apart).
struct CentreCut {
  using Coarse = SpheresTouch;
  const CutShape* cut;
  float skin = 0.0f;
  template <class Real>
  CG_HD bool refine(const Sphere<Real>& sa, const Sphere<Real>& sb, std::uint32_t a, std::uint32_t b) const {
    return !cut_apart(sa, sb, cut[a], cut[b], skin);
  }
  template <class Real>
  CG_HD bool operator()(const Sphere<Real>& sa, const Sphere<Real>& sb, std::uint32_t a,
                        std::uint32_t b) const {
    return Coarse{}(sa, sb, a, b) && refine(sa, sb, a, b);
  }
};

}  // namespace cg
