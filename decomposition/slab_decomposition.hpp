#pragma once
// Slab decomposition of space for the MPI run: pure geometry, no MPI, no CUDA (unit-tested with g++).
//
// Words used once and for all (as in Cabana's halo):
//   owner   the single rank whose slab holds a body's centre coordinate along the slab axis;
//   export  the bodies a rank sends to another rank (to their owner, or as ghosts);
//   import  the bodies a rank receives;
//   ghost   a body held by a rank that does not own it, so that the rank can test its owned bodies
//           against it.
//
// Slabs along axis k, P ranks, P-1 interior cuts c_1 <= c_2 <= ... <= c_{P-1}:
//
//         rank 0        rank 1        rank 2             rank P-1
//     (-inf ..... c_1)[c_1 ..... c_2)[c_2 ..... c_3) ... [c_{P-1} ..... +inf)
//
// Slabs are half-open; a centre exactly on a cut belongs to the UPPER slab (owner = number of cuts
// <= x). Equal cuts give empty slabs [c, c) that own nothing.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "engine.hpp"

namespace cg {

enum class Balance {
  count,  // cuts at quantiles of the centre coordinate: about the same number of bodies per rank
  width,  // cuts at equal widths over the global bounds
};

// Coordinate k (0 x, 1 y, 2 z) of v.
inline double component(const Vec3<double>& v, int k) { return k == 0 ? v.x : (k == 1 ? v.y : v.z); }

// The slab axis of a run: `forced` (0, 1, 2) if >= 0, else the axis of largest extent of the global
// bounds (ties: the lowest axis).
int choose_axis(const Bounds& global, int forced);

// Largest centre distance (along any axis) at which the engine can report two bodies in contact,
// as used for the ghost width: 2·r_max, plus a margin for the rounding of the local coordinates
// Real(world - origin) and of the contact test in a precision of machine epsilon `epsilon`;
// `extent` bounds |world - origin| of every centre.
double ghost_width(double r_max, double extent, double epsilon);

// The ghost width of a frame with this origin over the bodies' `global` bounds: ghost_width of their
// largest radius and of the largest distance of their boxes from the origin, grown by `reach` (bodies
// that may still move by reach/2 each, the origin with them).
double frame_ghost_width(const Bounds& global, const Vec3<double>& origin, double epsilon, double reach = 0);

// The largest distance, along any axis, of the bodies' `global` box from a frame's origin: the
// `extent` of ghost_width() and ghost_rule().
double frame_extent(const Bounds& global, const Vec3<double>& origin);

// How far from its centre, along the slab axis, a body must be held (owned or as a ghost) so that
// every contact is found by one rank: the ghost width of each body. A pair is reported by its
// anchor's owner (bodies.hpp: the smaller id, or the narrow body of a wide and a narrow one), which
// must hold the other body. Narrow bodies (r <= narrow) anchor every pair they are in but the ones with
// a narrow body of smaller id; a body's partner across a slab lies within r + r_partner of its centre.
// So a narrow body goes to the slabs within r + narrow (its anchors are narrow), a wide one to those
// within r + r_max (any body may anchor its pairs), each plus the rounding margin of ghost_width():
// the few large bodies of a scene go to every slab they reach, the small ones' halos stay small.
// uniform(w): every body within w, none wide (contactgrid simulate's steps; tests).
struct GhostRule {
  double narrow = 0;        // largest radius of a narrow body (+inf: none is wide)
  double narrow_reach = 0;  // a narrow body's width, beyond its radius (uniform: the whole width)
  double wide_reach = 0;    // a wide body's width, beyond its radius
  double margin = 0;        // in both reaches: the rounding margin (and the resident steps' skin)
  bool per_radius = true;   // the width grows with the body's radius (false: uniform)
  bool wide(double r) const { return r > narrow; }
  double width(double r) const { return (per_radius ? r : 0.0) + (wide(r) ? wide_reach : narrow_reach); }
  std::uint8_t wide_bit(double r) const { return wide(r) ? kWideBit : 0; }
  // The largest width of any body of radius <= r_max (the halo plan's sanity check).
  double max_width(double r_max) const { return width(r_max); }
  static GhostRule uniform(double w);
};

// The rule of a run from its global bounds: narrow = min(r_max, kLevelsSpread × the mean radius)
// (the bodies auto's levels treat as large are the wide ones; a scene of similar radii has none), the
// reaches narrow and r_max plus the margin of ghost_width(r_max, extent, epsilon) beyond 2·r_max.
// `reach` (the resident steps' skin: bodies that may still move by reach/2 each, the origin with them)
// grows the extent and the margin by it, as frame_ghost_width's.
GhostRule ghost_rule(const Bounds& global, double extent, double epsilon, double reach = 0);

// The slabs of a run.
//
// Invariants: cuts().size() == ranks() - 1; cuts are finite and non-decreasing; every finite
// coordinate has exactly one owner (half-open slabs, a coordinate on a cut goes to the upper slab);
// slab r is [lower(r), upper(r)) with lower(0) = -inf and upper(P-1) = +inf.
class SlabDecomposition {
 public:
  // Interior cuts (P-1 values, finite, non-decreasing; InputError otherwise) along `axis`.
  SlabDecomposition(int axis, std::vector<double> cuts);

  // One slab (a single rank) owning everything.
  static SlabDecomposition single(int axis) { return SlabDecomposition(axis, {}); }

  // balance = count: cuts at the quantiles of a sorted sample of centre coordinates. Cut r
  // (1 <= r < P) is sample[floor(r·S/P)], so with the full set of centres as the sample every
  // slab owns floor or ceil of N/P bodies (up to ties). An empty sample gives all cuts at 0.
  static SlabDecomposition from_sorted_sample(int axis, std::span<const double> sorted_sample, int ranks);

  // The same cuts from an unsorted sample: only the P-1 quantile positions are put in order
  // (successive selections on the remaining upper part; a sort above 64 ranks).
  static SlabDecomposition from_sample(int axis, std::vector<double> sample, int ranks);

  // balance = width: P slabs of equal width between lo and hi (the outer two still extend to ±inf).
  static SlabDecomposition equal_width(int axis, double lo, double hi, int ranks);

  int axis() const { return m_axis; }
  int ranks() const { return static_cast<int>(m_cuts.size()) + 1; }
  const std::vector<double>& cuts() const { return m_cuts; }
  double lower(int rank) const;  // -inf for rank 0
  double upper(int rank) const;  // +inf for rank P-1
  bool empty(int rank) const { return !(lower(rank) < upper(rank)); }

  // The owner of a centre coordinate x along the axis (x finite).
  int owner(double x) const;

  // Ranks r != owner(x) with a non-empty slab within distance w of x, ascending:
  // lower(r) <= x + w and x - w <= upper(r)  (the closed slab within w of x).
  // Calls f(r) for each. x + w and x - w are rounded, but rounding is monotone, so for any double
  // y with |x - y| <= w exactly, the slab holding y is always included.
  template <class F>
  void for_each_ghost_rank(double x, double w, F&& f) const;

 private:
  int m_axis = 0;
  std::vector<double> m_cuts;
};

// The owner and halo plans (who exports which rows to whom): decomposition/routing.hpp.

// ---- inline ---------------------------------------------------------------------------------------

template <class F>
void SlabDecomposition::for_each_ghost_rank(double x, double w, F&& f) const {
  // First rank with upper(r) >= x - w: the number of cuts < x - w. Last rank with lower(r) <= x + w:
  // the number of cuts <= x + w.
  const double below = x - w, above = x + w;
  int first = 0, last = 0;
  {
    std::size_t lo = 0, hi = m_cuts.size();
    while (lo < hi) {  // lower_bound(below)
      std::size_t mid = (lo + hi) / 2;
      if (m_cuts[mid] < below)
        lo = mid + 1;
      else
        hi = mid;
    }
    first = static_cast<int>(lo);
  }
  {
    std::size_t lo = 0, hi = m_cuts.size();
    while (lo < hi) {  // upper_bound(above)
      std::size_t mid = (lo + hi) / 2;
      if (m_cuts[mid] <= above)
        lo = mid + 1;
      else
        hi = mid;
    }
    last = static_cast<int>(lo);
  }
  const int self = owner(x);
  for (int r = first; r <= last; ++r) {
    if (r != self && !empty(r)) f(r);
  }
}

}  // namespace cg
