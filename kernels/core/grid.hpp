#pragma once
// Le Grand's uniform grid (GPU Gems 3, ch. 32): the index math shared by both backends.
//
// Cells are cubes of edge `cell_size` >= the largest bounding diameter (plus a rounding margin), so
// along each axis a body's bounding box [c - r, c + r] covers one cell or two adjacent ones: a body
// overlaps at most 8 cells, its home cell (holding the centre) and up to 7 phantom cells.
//
// Cell type = parity of the cell coordinates (x&1 | (y&1)<<1 | (z&1)<<2), 8 types. The cell key puts
// the type in the top bits, so after the radix sort the entries of type-0 cells come first, then
// type 1, ...: processing the sorted array in order *is* Le Grand's 8 passes by cell type.
//
//     key = type << half_bits | (x>>1) + hx * ((y>>1) + hy * (z>>1)),   hx = ceil(dims.x / 2), ...
//
// Exactly-once rule. Two bodies whose boxes overlap share a box of common cells; along each axis the
// common range is one cell, or two cells when both bodies span the same two cells. Common cells all
// have distinct types, so exactly one common cell has the smallest type; the pair is tested there and
// nowhere else. With only the control byte of each body (parity of its lowest cell, and which axes it
// spans two cells on) a cell decides that locally: along an axis where the two bodies share two cells,
// the smallest type has bit 0 there, so a cell whose type has bit 1 on such an axis skips the pair.
//
// Note (deliberate deviation from GPU Gems): cells holding only phantom entries are NOT skipped. Two
// touching spheres can share only a cell that is home to neither (spheres near a cell corner, see the
// test PhantomOnlyCellHoldsContact), so skipping phantom-only cells loses contacts.
#include <cstdint>
#include <limits>

#include "core/config.hpp"
#include "core/vec3.hpp"

namespace cg {

// Device-copyable grid description, in the real type of the run. Built on the host by plan_grid().
template <class Real>
struct GridParams {
  Real inv_cell;          // 1 / cell_size, rounded to Real
  std::uint32_t base[3];  // frame cell coordinate of this grid's first cell (even: parity is global)
  std::uint32_t dims[3];  // cells per axis
  std::uint32_t half[3];  // ceil(dims / 2): super-cells (2x2x2 blocks) per axis
  int half_bits;          // bits of the super-cell index; key bits = half_bits + 3
  Real radius_margin;     // added to every packed radius: mixed's broad_margin(), else 0 (r + 0 == r)
};

// The cells one body overlaps: lowest cell coordinates and, per axis, whether it spans two cells.
struct BodyCells {
  std::uint32_t lo[3];
  std::uint32_t spill;  // bit k set: the body also overlaps cell lo[k] + 1 along axis k
};

// floor(v / cell) - base, clamped to the grid. Monotone in v, so boxes that overlap share a cell.
template <class Real>
CG_HD std::uint32_t cell_coord(Real v, Real inv_cell, std::uint32_t base, std::uint32_t dims) {
  Real f = v * inv_cell;
  if (!(f >= static_cast<Real>(base))) return 0;  // below the grid (or NaN: caught by validation)
  if (f >= static_cast<Real>(base + dims - 1)) return dims - 1;
  return static_cast<std::uint32_t>(f) - base;  // truncation == floor for f >= 0
}

// The cells of the box [c − e, c + e] about the centre of s, half-extents e (each at most s.r).
template <class Real>
CG_HD BodyCells box_cells(const Sphere<Real>& s, Real ex, Real ey, Real ez, const GridParams<Real>& g) {
  BodyCells bc;
  const Real c[3] = {s.x, s.y, s.z}, e[3] = {ex, ey, ez};
  bc.spill = 0;
  for (int k = 0; k < 3; ++k) {
    std::uint32_t lo = cell_coord(c[k] - e[k], g.inv_cell, g.base[k], g.dims[k]);
    std::uint32_t hi = cell_coord(c[k] + e[k], g.inv_cell, g.base[k], g.dims[k]);
    bc.lo[k] = lo;
    if (hi > lo) bc.spill |= 1u << k;  // hi <= lo + 1 by the cell-size margin of plan_grid()
  }
  return bc;
}

// The half-extent of a body's box in every broad phase: its radius widened by 16 units of rounding
// (8·ε of Real), so that every pair the pair stage's sphere test accepts has overlapping boxes. That
// test, d² <= (ra + rb)² in Real on the packed centres, accepts only |Δ| <= (ra + rb)(1 + 4.1u) per
// axis (u = ε/2: one rounding of each difference, square, sum and of the radii's sum), and the boxes'
// faces c ± box_radius(r), rounded, keep the order of the exact ones (rounding is monotone). So the
// grid finds every accepted pair in a shared cell, whatever the cell edge, and every broad phase
// (core/broad.hpp) finds the same candidates. The cell edge's margin (grid_plan.cpp: min_cell_size,
// 16·ε relative) covers it: a box still spans at most two cells per axis.
template <class Real>
CG_HD Real box_radius(Real r) {
  return r + r * (Real(8) * std::numeric_limits<Real>::epsilon());
}

// The cells of a body's bounding sphere (its box [c − R, c + R], R = box_radius(r)). Scenes of
// ellipsoids with the centre cut take the box of each shape instead (core/centre_cut.hpp: cut_cells).
template <class Real>
CG_HD BodyCells body_cells(const Sphere<Real>& s, const GridParams<Real>& g) {
  const Real e = box_radius(s.r);
  return box_cells(s, e, e, e, g);
}

CG_HD int popcount3(std::uint32_t m) { return int(m & 1u) + int((m >> 1) & 1u) + int((m >> 2) & 1u); }

// Number of (cell, body) entries a body produces: 1, 2, 4 or 8.
CG_HD std::uint32_t entry_count(const BodyCells& bc) { return 1u << popcount3(bc.spill); }

// Control byte: bits 0-2 parity of the lowest cell per axis, bits 3-5 spill per axis.
CG_HD std::uint8_t control_bits(const BodyCells& bc) {
  return static_cast<std::uint8_t>((bc.lo[0] & 1u) | ((bc.lo[1] & 1u) << 1) | ((bc.lo[2] & 1u) << 2) |
                                   (bc.spill << 3));
}

template <class Key, class Real>
CG_HD Key cell_key(std::uint32_t x, std::uint32_t y, std::uint32_t z, const GridParams<Real>& g) {
  Key type = Key((x & 1u) | ((y & 1u) << 1) | ((z & 1u) << 2));
  Key lin = Key(x >> 1) + Key(g.half[0]) * (Key(y >> 1) + Key(g.half[1]) * Key(z >> 1));
  return (type << g.half_bits) | lin;
}

template <class Key>
CG_HD std::uint32_t key_type(Key key, int half_bits) {
  return static_cast<std::uint32_t>(key >> half_bits) & 7u;
}

// The key of the m-th cell of a body, m in [0, entry_count): m enumerates the spilled axes.
template <class Key, class Real>
CG_HD Key body_cell_key(const BodyCells& bc, std::uint32_t m, const GridParams<Real>& g) {
  std::uint32_t off[3] = {0, 0, 0};
  for (int k = 0; k < 3; ++k) {
    if (bc.spill & (1u << k)) {
      off[k] = m & 1u;
      m >>= 1;
    }
  }
  return cell_key<Key>(bc.lo[0] + off[0], bc.lo[1] + off[1], bc.lo[2] + off[2], g);
}

// The same key from the key of the body's lowest cell and its control byte (control_bits: parity of
// lo, spilled axes): along an axis the linear part grows by one only where lo is odd (lo + 1 starts the
// next super-cell), and the type bit flips with the offset. (The device's entries stage: a key and a
// byte per body instead of its sphere and shape.)
template <class Key, class Real>
CG_HD Key spilled_cell_key(Key lo_key, std::uint32_t ctrl, std::uint32_t m, const GridParams<Real>& g) {
  const std::uint32_t parity = ctrl & 7u, spill = (ctrl >> 3) & 7u;
  std::uint32_t off = 0;
  for (int k = 0; k < 3; ++k) {
    if (spill & (1u << k)) {
      off |= (m & 1u) << k;
      m >>= 1;
    }
  }
  const std::uint32_t up = off & parity;
  const Key lin = (lo_key & ((Key(1) << g.half_bits) - Key(1))) + Key(up & 1u) +
                  ((up & 2u) ? Key(g.half[0]) : Key(0)) +
                  ((up & 4u) ? Key(g.half[0]) * Key(g.half[1]) : Key(0));
  return (Key(parity ^ off) << g.half_bits) | lin;
}

// True when the pair of bodies with control bytes ci, cj, both present in a cell of type `type`,
// is tested in that cell (the common cell of smallest type). See the file comment.
CG_HD bool test_in_cell(std::uint8_t ci, std::uint8_t cj, std::uint32_t type) {
  std::uint32_t two_common =
      ~(std::uint32_t(ci) ^ std::uint32_t(cj)) & (std::uint32_t(ci) >> 3) & (std::uint32_t(cj) >> 3) & 7u;
  return (two_common & type) == 0u;
}

}  // namespace cg
