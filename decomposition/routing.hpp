#pragma once
// Routing: who sends which rows to whom. Pure host code (no MPI, no CUDA); comm/ executes it.
//
// Every plan is count → exclusive scan → fill over the rows 0 … n-1, in parallel over a static split
// of the rows into chunks: each chunk counts its rows per destination, one scan turns the counts into
// each chunk's first slot per destination, each chunk fills its slots. The result does not depend on
// the number of threads: rows for rank r are grouped together (ranks ascending) and, within a
// destination, keep ascending row order. No index list is built unless the exported value is the index.
//
// The two plans of a distributed run are destination rules over the slab axis coordinate of a row:
//   to_owner        redistribution: every row to the owner of its centre (this rank included);
//   to_ghost_ranks  halo: every owned row to each OTHER rank whose non-empty slab lies within the
//                   ghost width (SlabDecomposition::for_each_ghost_rank).
// make_owner_plan and make_halo_plan are those rules exporting the row indices (unit-tested);
// the run exports the rows' BodyRecords with the same rules and the same route().
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "engine.hpp"
#include "slab_decomposition.hpp"

namespace cg {

// One body in flight between ranks: a global id and a bounding sphere. Sent as bytes (homogeneous
// nodes). The shape of a body of a scene with ellipsoids travels as a ShapeRecord in a parallel
// array, routed by the same rule (so in the same order): a sphere-only scene moves BodyRecords only.
struct BodyRecord {
  Vec3<double> position;
  double radius;
  std::int64_t id;
};
static_assert(std::is_trivially_copyable_v<BodyRecord>);

// A body's shape rows (BodiesView::shape, semi_axes, orientation), parallel to its BodyRecord.
struct ShapeRecord {
  Quat<double> orientation;
  Vec3<double> semi_axes;
  Shape shape;
};
static_assert(std::is_trivially_copyable_v<ShapeRecord>);

// Static split of [0, n) into `parts` contiguous chunks (deterministic, whatever the team size):
// one chunk below 2^14 rows, else one per thread.
struct Chunks {
  std::size_t n;
  int parts;
  Chunks(std::size_t n_, int threads)
      : n(n_), parts(n_ < (std::size_t(1) << 14) ? 1 : std::max(1, threads)) {}
  std::size_t begin(int t) const { return static_cast<std::size_t>((std::uint64_t)n * t / parts); }
  std::size_t end(int t) const { return begin(t + 1); }
};

// Smallest i in [0, n) with bad(i), or n. Parallel; the answer does not depend on the threads.
template <class Bad>
std::size_t first_bad(std::size_t n, int threads, Bad&& bad) {
  const Chunks c(n, threads);
  std::vector<std::size_t> found(static_cast<std::size_t>(c.parts), n);
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    for (std::size_t i = c.begin(t), e = c.end(t); i < e; ++i) {
      if (bad(i)) {
        found[static_cast<std::size_t>(t)] = i;
        break;
      }
    }
  }
  return *std::min_element(found.begin(), found.end());
}

// Rows exported to every rank, grouped by destination: the rows for rank r are
// rows[offsets[r] .. offsets[r+1]), in ascending source-row order. offsets.size() == ranks + 1.
template <class T, class Alloc = HostAllocator<T>>
struct Exports {
  std::vector<std::size_t> offsets;
  std::vector<T, Alloc> rows;

  int ranks() const { return static_cast<int>(offsets.size()) - 1; }
  std::size_t count(int rank) const { return offsets[rank + 1] - offsets[rank]; }
  std::span<const T> to(int rank) const { return {rows.data() + offsets[rank], count(rank)}; }
  std::size_t total() const { return rows.size(); }
  std::vector<std::uint64_t> counts() const {  // per destination rank
    std::vector<std::uint64_t> c(offsets.size() - 1);
    for (std::size_t r = 0; r < c.size(); ++r) c[r] = offsets[r + 1] - offsets[r];
    return c;
  }
};

// The plan as row indices (what the unit tests and library users read).
using ExportPlan = Exports<std::size_t, std::allocator<std::size_t>>;

// Rows 0 … n-1 routed to `ranks` destinations: `dest(i, emit)` calls emit(r) for each destination
// rank of row i (any number of times, ascending), `make(i)` is the exported value. Parallel count →
// scan → fill by `threads` threads (see the file comment).
template <class T, class Alloc = HostAllocator<T>, class Dest, class Make>
Exports<T, Alloc> route(std::size_t n, int ranks, int threads, Dest&& dest, Make&& make) {
  const std::size_t p = static_cast<std::size_t>(ranks);
  const Chunks c(n, threads);
  const std::size_t parts = static_cast<std::size_t>(c.parts);
  std::vector<std::uint64_t> at(parts * p, 0);  // per chunk and rank: count, then first slot
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    std::uint64_t* mine = at.data() + static_cast<std::size_t>(t) * p;
    for (std::size_t i = c.begin(t), e = c.end(t); i < e; ++i) dest(i, [&](int r) { ++mine[r]; });
  }
  Exports<T, Alloc> out;
  out.offsets.assign(p + 1, 0);
  std::uint64_t total = 0;
  for (std::size_t r = 0; r < p; ++r) {
    for (std::size_t t = 0; t < parts; ++t) {
      const std::uint64_t k = at[t * p + r];
      at[t * p + r] = total;
      total += k;
    }
    out.offsets[r + 1] = total;
  }
  out.rows.resize(total);
  T* rows = out.rows.data();
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    std::uint64_t* next = at.data() + static_cast<std::size_t>(t) * p;
    for (std::size_t i = c.begin(t), e = c.end(t); i < e; ++i)
      dest(i, [&](int r) { rows[next[r]++] = make(i); });
  }
  return out;
}

// Destination rule of redistribution: row i goes to the owner of coordinate(i).
template <class Coordinate>
auto to_owner(const SlabDecomposition& slabs, Coordinate coordinate) {
  return [&slabs, coordinate](std::size_t i, auto&& emit) { emit(slabs.owner(coordinate(i))); };
}

// Destination rule of the halo: row i goes to every other rank within `width` of coordinate(i).
template <class Coordinate>
auto to_ghost_ranks(const SlabDecomposition& slabs, Coordinate coordinate, double width) {
  return [&slabs, coordinate, width](std::size_t i, auto&& emit) {
    slabs.for_each_ghost_rank(coordinate(i), width, emit);
  };
}

// The halo's rule with a width per row (GhostRule): row i goes to every other rank within width(i)
// of coordinate(i).
template <class Coordinate, class Width>
auto to_ghost_ranks_by(const SlabDecomposition& slabs, Coordinate coordinate, Width width) {
  return [&slabs, coordinate, width](std::size_t i, auto&& emit) {
    slabs.for_each_ghost_rank(coordinate(i), width(i), emit);
  };
}

// The halo plan's preconditions (InputError otherwise): `width` finite and >= 0, and every row
// 0 … n-1 owned by `self` ("halo plan: body <row> at <x> is not owned by rank <self>"). Parallel.
template <class Coordinate>
void check_halo_rows(const SlabDecomposition& slabs, int self, std::size_t n, Coordinate coordinate,
                     double width, int threads) {
  if (!(width >= 0) || !std::isfinite(width))
    throw InputError("halo plan: ghost width is not a finite value >= 0");
  const std::size_t bad =
      first_bad(n, threads, [&](std::size_t i) { return slabs.owner(coordinate(i)) != self; });
  if (bad < n) {
    throw InputError("halo plan: body " + std::to_string(bad) + " at " + std::to_string(coordinate(bad)) +
                     " is not owned by rank " + std::to_string(self));
  }
}

// Redistribution: every body goes to its owner (including this rank itself: bodies this rank owns
// appear in to(self)). `coordinate[i]` is body i's centre coordinate along the slab axis.
ExportPlan make_owner_plan(const SlabDecomposition& slabs, std::span<const double> coordinate,
                           int threads = 1);

// Halo plan of the bodies a rank owns (all bodies in `coordinate` must be owned by `self`; InputError
// otherwise): each goes as a ghost to every OTHER rank whose non-empty slab lies within `ghost_width`
// of its centre coordinate — not only to the neighbours: slabs thinner than the ghost width make a
// body a ghost further away. to(self) is always empty.
//
// Invariant (what the MPI run relies on): with ghost_width >= the largest centre distance of a
// contacting pair (see ghost_width()), for every contacting pair (i, j) with i < j the owner of i
// holds j, owned or as a ghost. Hence the owner of the smaller id reports the pair (report mask =
// owned) and every contact is found exactly once.
ExportPlan make_halo_plan(const SlabDecomposition& slabs, int self, std::span<const double> coordinate,
                          double ghost_width, int threads = 1);

// The same with a ghost width per body (GhostRule: rule.width of its radius): every contacting pair is
// held by its anchor's owner (bodies.hpp), which reports it.
ExportPlan make_halo_plan(const SlabDecomposition& slabs, int self, std::span<const double> coordinate,
                          std::span<const double> radius, const GhostRule& rule, int threads = 1);

}  // namespace cg
