#pragma once
// What every broad phase shares (grid, levels, sweep, brute; both backends): the box test, the report
// rule, the levels of the hierarchy of grids and the sortable key of the sweep.
//
// Every broad phase hands the pair stage's test (core/narrow.hpp: SpheresTouch, CellRule, Fp64Touch;
// core/centre_cut.hpp: CentreCut) the pairs whose boxes (c ± box_radius(r), core/grid.hpp) may meet,
// each once, and keeps those it accepts. The sphere tests accept only pairs whose boxes overlap
// (box_radius), so with those filters every broad phase proposes exactly the pairs the test accepts:
// the same candidate list, and the same contacts. The cell rule (CandidateFilter::cells) keeps every
// pair a broad phase proposes (the grid: sharing a cell; sweep and brute: overlapping boxes), and the
// centre cut's grid cells are of the shapes' boxes: their candidates differ between broad phases, the
// narrow stage's rejections make the contacts the same.
#include <cstdint>
#include <cstring>
#include <limits>

#include "bodies.hpp"
#include "core/grid.hpp"
#include "core/vec3.hpp"

namespace cg {

// True when the boxes of a and b (half-extent box_radius(r) about the centre) overlap along every
// axis, each face rounded once (the comparison of the sweep along its axis, too).
template <class Real>
CG_HD bool boxes_overlap(const Sphere<Real>& a, const Sphere<Real>& b) {
  const Real ea = box_radius(a.r), eb = box_radius(b.r);
  return a.x + ea >= b.x - eb && b.x + eb >= a.x - ea && a.y + ea >= b.y - eb && b.y + eb >= a.y - ea &&
         a.z + ea >= b.z - eb && b.z + eb >= a.z - ea;
}

// The report rule of a pair of input indices a != b (bodies.hpp): reported when its anchor's mask has
// kReportedBit and not both have kPairedBit; every pair without a mask (report null). The anchor is
// the smaller of the two in (kWideBit, index) order: the smaller index, or the narrow body of a wide
// and a narrow one.
CG_HD bool pair_reported(const std::uint8_t* report, std::uint32_t a, std::uint32_t b) {
  if (report == nullptr) return true;
  const std::uint8_t ra = report[a], rb = report[b];
  const bool a_first = (ra & kWideBit) != (rb & kWideBit) ? !(ra & kWideBit) : a < b;
  return ((a_first ? ra : rb) & kReportedBit) && !((ra & kPairedBit) && (rb & kPairedBit));
}

// ---- levels: a hierarchy of grids (kernels/broad_phase.hpp: plan_levels) ---------------------------
//
// Level l holds the bodies whose broad-phase radius (packed, with mixed's margin and a skin's
// inflation) is at most top[l] and above top[l − 1]; its grid's cell edge covers top[l], so within a
// level Le Grand's rules hold (home and phantom cells, the cell of smallest type). A pair of two
// levels is found from the smaller body's side: it takes the cells its box overlaps in the larger
// body's level (at most two per axis: its box is smaller than that level's cells) and meets there the
// larger body's entries, the pair tested in their common cell of smallest type (test_in_cell with
// both control bytes of that level), so once. Keys: level << (half_bits + 3) | cell_key, half_bits
// the largest of the levels' (each level's GridParams carries that common half_bits).
constexpr int kMaxLevels = 16;

template <class Real>
struct LevelParams {
  int count;                          // levels, 1 … kMaxLevels
  int key_shift;                      // half_bits + 3: the level's bits start here
  Real top[kMaxLevels];               // largest radius of each level (the last: +inf)
  GridParams<Real> grid[kMaxLevels];  // each level's grid (common origin and half_bits)
};

template <class Real>
CG_HD int level_of(Real r, const LevelParams<Real>& lp) {
  int l = 0;
  while (l + 1 < lp.count && r > lp.top[l]) ++l;
  return l;
}

template <class Key>
CG_HD int key_level(Key key, int key_shift) {
  return static_cast<int>(key >> key_shift);
}

// The first index f in [lo, hi) of the ascending keys with keys[f] >= key (hi: none).
template <class Key, class Index>
CG_HD Index lower_bound_key(const Key* keys, Index lo, Index hi, Key key) {
  Index len = hi - lo;
  while (len > 0) {
    const Index half = len / 2;
    if (keys[lo + half] < key) {
      lo += half + 1;
      len -= half + 1;
    } else {
      len = half;
    }
  }
  return lo;
}

// The cells body a of level la looks up in the larger levels (both backends and both uses below run
// this one routine: host/levels.cpp, cuda/levels.cuh): in every larger level l whose run of the sorted
// entry keys [begin[l], begin[l + 1]) is not empty, the cells of a's box in l's grid (cells_in(grid):
// its BodyCells there), each as visit(key, lo, hi, a's control byte there, the key's cell type).
template <class Real, class Key, class Index, class CellsIn, class Visit>
CG_HD void for_larger_level_cells(int la, const LevelParams<Real>& lp, const Index* begin, CellsIn&& cells_in,
                                  Visit&& visit) {
  const int half_bits = lp.key_shift - 3;
  for (int l = la + 1; l < lp.count; ++l) {
    const Index lo = begin[l], hi = begin[l + 1];
    if (lo == hi) continue;
    const GridParams<Real> g = lp.grid[l];
    const BodyCells bc = cells_in(g);
    const std::uint8_t ca = control_bits(bc);
    const Key level = Key(l) << lp.key_shift;
    for (std::uint32_t m = 0, cells = entry_count(bc); m < cells; ++m) {
      const Key k = level | body_cell_key<Key>(bc, m, g);
      visit(k, lo, hi, ca, key_type(k, half_bits));
    }
  }
}

// The pairs across levels of body a in level la, from its side: each of its cells in the larger levels
// (for_larger_level_cells) looked up in that level's run, and every body b met there that the pair is
// tested with in that cell (test_in_cell with both control bytes of level l: the common cell of
// smallest type) and that the report rule keeps: visit(b). Returns the pairs visited (the pair tests).
template <class Real, class Key, class Index, class CellsIn, class Visit>
CG_HD std::uint64_t cross_level_pairs(std::uint32_t a, int la, const LevelParams<Real>& lp, const Key* keys,
                                      const std::uint32_t* body, const Index* begin, const std::uint8_t* ctrl,
                                      const std::uint8_t* report, CellsIn&& cells_in, Visit&& visit) {
  std::uint64_t tests = 0;
  for_larger_level_cells<Real, Key>(
      la, lp, begin, cells_in, [&](Key k, Index lo, Index hi, std::uint8_t ca, std::uint32_t type) {
        for (Index f = lower_bound_key(keys, lo, hi, k); f < hi && keys[f] == k; ++f) {
          const std::uint32_t b = body[f];
          if (!test_in_cell(ca, ctrl[b], type) || !pair_reported(report, a, b)) continue;
          ++tests;
          visit(b);
        }
      });
  return tests;
}

// The pair estimate's share of body a across levels (pair_estimate.hpp): the entries of the cells
// cross_level_pairs walks, found by two binary searches a cell and not walked, so that a pile of
// larger bodies that every small body nearby would meet is counted before any pair is tested. At
// least cross_level_pairs' tests (the cell rule and the report rule only drop some).
template <class Real, class Key, class Index, class CellsIn>
CG_HD std::uint64_t cross_level_bound(int la, const LevelParams<Real>& lp, const Key* keys,
                                      const Index* begin, CellsIn&& cells_in) {
  std::uint64_t tests = 0;
  for_larger_level_cells<Real, Key>(
      la, lp, begin, cells_in, [&](Key k, Index lo, Index hi, std::uint8_t, std::uint32_t) {
        const Index f = lower_bound_key(keys, lo, hi, k);
        if (f == hi || keys[f] != k) return;
        const Index end = k == Key(~Key(0)) ? hi : lower_bound_key(keys, f, hi, Key(k + 1));
        tests += end - f;
      });
  return tests;
}

// ---- sweep: Baraff's sort and sweep along one axis --------------------------------------------------

// The bits of v, as an unsigned integer of the same order (for the radix sort of the boxes' lower
// faces): positive values with the sign bit set, negative ones with every bit flipped.
CG_HD std::uint32_t orderable_bits(float v) {
#if defined(__CUDA_ARCH__)
  const std::uint32_t u = __float_as_uint(v);
#else
  std::uint32_t u;
  std::memcpy(&u, &v, sizeof(u));
#endif
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}
CG_HD std::uint64_t orderable_bits(double v) {
#if defined(__CUDA_ARCH__)
  const std::uint64_t u = static_cast<std::uint64_t>(__double_as_longlong(v));
#else
  std::uint64_t u;
  std::memcpy(&u, &v, sizeof(u));
#endif
  return (u & 0x8000000000000000ull) ? ~u : (u | 0x8000000000000000ull);
}

template <class Real>
CG_HD Real axis_of(const Sphere<Real>& s, int axis) {
  return axis == 0 ? s.x : (axis == 1 ? s.y : s.z);
}

}  // namespace cg
