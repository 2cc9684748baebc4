#pragma once
// The CPU backend's stages, one file each (pack.cpp, entries.cpp, sort.cpp, pairs.cpp, order.cpp,
// narrow.cpp), sequenced by host_backend.cpp. All memory is HOST memory; `threads` OpenMP threads
// (> 0). Every decision and value comes from the CG_HD functions of kernels/core/, in the order the
// CUDA kernels use, so this backend is the oracle of the CUDA one.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <type_traits>
#include <vector>

#include "core/broad.hpp"
#include "core/centre_cut.hpp"
#include "core/grid.hpp"
#include "core/narrow.hpp"
#include "core/shape_narrow.hpp"
#include "core/skin.hpp"
#include "engine.hpp"
#include "host/scratch_pool.hpp"

namespace cg::detail::host {

// Below this many items a loop runs on the calling thread: waking a team costs more than it saves.
constexpr std::size_t k_parallel_min = 32768;

// Exclusive scan of `counts` into `offsets` (size + 1 values, the last the total); returns the total.
template <class Counts, class Offsets>
typename Offsets::value_type exclusive_scan_into(const Counts& counts, Offsets& offsets) {
  using Acc = typename Offsets::value_type;
  offsets.resize(counts.size() + 1);
  Acc sum = 0;
  for (std::size_t i = 0; i < counts.size(); ++i) {
    offsets[i] = sum;
    sum += counts[i];
  }
  offsets[counts.size()] = sum;
  return sum;
}

// pack's output, per body in input order.
template <class Real>
struct PackedBodies {
  Array<Sphere<Real>> spheres;  // local frame: Real(world - origin)
  Real inflation = 0;           // added to every radius by the pair stage (cells, test)
  Array<BodyCells> cells;       // freed by fill_entries
  // pack for the cell sort (`blocks`): in place of cells and ctrl, each body's index << 32 | its
  // block_key, one array that block_sort sorts as it is (freed there)
  Array<std::uint64_t> block;
  Array<std::uint8_t> ctrl;    // control_bits (its spill bits give the entry count)
  Array<std::uint32_t> count;  // entry_count (level_entries reads it; pack leaves it empty)
  Array<CutShape> cut;         // CandidateFilter::centre_cut: cut_shape() of every body
  // a skin's build of the centre cut: its margin (CentreCut::skin, 2·inflation); its cells stay the
  // inflated bounding spheres' (core/centre_cut.hpp)
  float cut_skin = 0;
  Array<std::uint8_t> level;  // BroadPhase::levels: the level of every body (level_cells)
  // the cells of the shapes' boxes (cut_cells): a fresh call's centre cut
  bool box_cells() const { return !cut.empty() && !(cut_skin > 0); }
};

// (cell key, body) entries; after fill_entries body-ascending, or grouped by the top digit of the key
// (digit_start not empty: group d = [digit_start[d], digit_start[d + 1]) holds the keys whose bits from
// digit_shift up make d, body-ascending); key-ascending (stable) after sort.
template <class Key>
struct Entries {
  Array<Key> keys;
  Array<std::uint32_t> body;
  std::vector<std::size_t> digit_start;
  int digit_shift = 0;
  std::size_t size() const { return keys.size(); }
};

// The walk's bodies of the sorted entries, structure of arrays: each entry's packed sphere (inflated by
// a skin) and control byte beside it, so that the walk reads memory in sequence and its inner loop
// vectorises; eight zero entries past the end (the four- and eight-lane walks read past a cell's end,
// those lanes masked off). The pair stage gathers them after the entry sort; the cell sort writes them.
template <class Real>
struct EntryBodies {
  Array<Real> x, y, z, r;
  Array<std::uint32_t> ctrl;  // control_bits, widened: the inner loop's lanes are 32 bits
  Sphere<Real> sphere(std::size_t e) const { return {x[e], y[e], z[e], r[e]}; }
};
constexpr std::size_t k_entry_pad = 8;

// Sizes eb for n entries and zeroes its padding.
template <class Real>
void resize_entry_bodies(EntryBodies<Real>& eb, std::size_t n) {
  for (Array<Real>* a : {&eb.x, &eb.y, &eb.z, &eb.r}) {
    a->resize(n + k_entry_pad);
    std::fill(a->begin() + std::ptrdiff_t(n), a->end(), Real(0));
  }
  eb.ctrl.resize(n + k_entry_pad);
  std::fill(eb.ctrl.begin() + std::ptrdiff_t(n), eb.ctrl.end(), 0u);
}

// Candidate pairs of local indices a < b, packed as a << id_bits | b: a plain (a, b) array, ascending
// after order_candidates (so a list can be kept across calls and handed to narrow again).
struct CandidatePairs {
  Array<std::uint64_t> ab;
  int id_bits = 1;
  CandidateFilter filter = CandidateFilter::spheres_touch;  // how the pair stage filtered them
  std::size_t size() const { return ab.size(); }
  std::uint32_t a(std::size_t k) const { return static_cast<std::uint32_t>(ab[k] >> id_bits); }
  std::uint32_t b(std::size_t k) const {
    return static_cast<std::uint32_t>(ab[k] & ((std::uint64_t(1) << id_bits) - 1));
  }
};

// The candidates kept across calls (EngineOptions::skin) and the state they were built from: the
// bodies' positions, radii and report mask (empty: none).
struct KeptCandidates {
  CandidatePairs pairs;
  std::vector<Vec3<double>> position;
  std::vector<double> radius;
  std::vector<std::uint8_t> report;
  // a list cut by the centre line (pairs.filter centre_cut): the shapes it was built from
  std::vector<Shape> shape;
  std::vector<Vec3<double>> semi_axes;
  std::vector<Quat<double>> orientation;
  // a check of a cut list saw a body turn: later builds keep the bounding spheres (core/skin.hpp:
  // skin_cut_wanted); for the engine's life
  bool turning = false;
};

// skin: what moved since `kept` was built (same body count): max |x − x_ref| (a cut list: the largest
// move of a body's point, turned_motion), max radius growth, whether the report mask or (a cut list)
// a body's kind or semi-axes changed. keep_candidates: `c` (moved, not copied: the narrow stage then
// reads the kept list) and the state of `bodies` into `kept`.
Motion measure_motion(const BodiesView& bodies, const KeptCandidates& kept, int threads);
void keep_candidates(const BodiesView& bodies, CandidatePairs&& c, KeptCandidates& kept);

// pack: world (double) → local Real spheres; per body its cells (of the sphere inflated by
// `inflation`, 0 without a skin) and control byte. cells_too false: the spheres only
// (the reuse of kept candidates needs no grid). `world` (may be null): also the world rows of every
// body as one Sphere<double> each (x, y, z, r: the input's doubles, one cache line a body), which the
// narrow stage reads at random in place of the input's two arrays. `blocks` (with cells_too, for the
// cell sort: cell_sort_packs_blocks): each body's block_key in out.block in place of its cells and
// control byte, a quarter of their bytes, which block_sort sorts as they are.
template <class Real>
void pack(const BodiesView& bodies, const Vec3<double>& origin, const GridParams<Real>& g, Real inflation,
          bool cells_too, int threads, PackedBodies<Real>& out, Array<Sphere<double>>* world = nullptr,
          bool blocks = false);

// pack_shapes (scenes with ellipsoids): pack_shape() of every body, input order.
template <class Real>
void pack_shapes(const BodiesView& bodies, int threads, std::vector<PackedShape<Real>>& out);

// cut_shapes (CandidateFilter::centre_cut): cut_shape() of every packed shape, input order.
template <class Packed>
void cut_shapes(const std::vector<PackedShape<Packed>>& shapes, int threads, Array<CutShape>& out);

// shape_cells (CandidateFilter::centre_cut, after cut_shapes; pack made the spheres only): the cells
// and control byte of each body from the box of its shape instead of its bounding sphere
// (core/centre_cut.hpp: cut_cells).
template <class Real>
void shape_cells(const GridParams<Real>& g, int threads, PackedBodies<Real>& bodies);

// sphere_cells: pack's cells and control byte of every packed sphere, for a pack that
// made the spheres only (the cell list's grid failed: cell_list_keys).
template <class Real>
void sphere_cells(const GridParams<Real>& g, int threads, PackedBodies<Real>& bodies);

// entries: the (cell key, body) entries of p.cells in body order (entry counts from the control bytes
// summed and scanned per fixed block of bodies, then a fill). With CONTACTGRID_HOST_ENTRIES=grouped
// and the sort's key_bits (> 11, from 32768 bodies): grouped by the top digit of their key (up to 8 of
// the key_bits bits), a counting pass and then each entry written to its group (out.digit_start),
// which is the sort's first pass (body order still where one group would hold too many of the
// entries). Returns the number of entries; frees p.cells and p.count.
template <class Real, class Key>
std::uint64_t fill_entries(PackedBodies<Real>& p, const GridParams<Real>& g, int threads, Entries<Key>& out,
                           int key_bits = 0);

// sort: stable radix sort of the entries by cell key over key_bits bits (entries grouped by their top
// digit: each group by its low bits). The same sorted entries from either fill.
template <class Key>
void sort_entries(Entries<Key>& e, int key_bits, int threads);

// ---- the cell sort (host/cell_sort.cpp): the grid's sorted entries without a body-order array ----
// The bodies sorted by the super-cell of their lowest cell (block_sort, stage entries: a stable radix
// sort of one key a body, then their spheres and control bytes gathered into that order), then the
// entries counted and written by cell from that order (cell_sort, stage sort): each body's cells lie
// within one layer of super-cells of its own, so both passes touch the counters and the outputs in a
// few sliding windows rather than at random. The entries come out key-ascending with the walk's
// bodies beside them (EntryBodies: no gather in the pair stage), but within a cell in the bodies'
// spatial order, not in body order: the walk tests each pair as (lower, higher) body, and the order
// stage sorts the candidates, so the candidates, pair tests and contacts are the entry sort's.
// cell_sort_wanted: CONTACTGRID_HOST_ENTRIES unset, `cells` or `cells-via-cells`, no report mask, and a
// grid of at most about four cells a body (the counters are a window of the grid's cells a thread) and
// 2^k_block_bits super-cells.
// A body of the order as the entries' gather reads it: one record, the few bytes of one or two cache
// lines, where six arrays would cost a line each.
template <class Real>
struct OrderedBody {
  Real x, y, z, r;     // the packed sphere (r inflated by a skin)
  std::uint32_t body;  // input index
  std::uint32_t ctrl;  // control byte, widened as the walk's bodies hold it
};
template <class Real>
struct BlockOrder {
  Array<std::uint32_t> block;       // super-cell index of each body's lowest cell, ascending
  Array<std::uint8_t> ctrl;         // control byte of each, alongside
  Array<OrderedBody<Real>> bodies;  // alongside (input indices ascending within a super-cell's group)
};
template <class Real>
bool cell_sort_wanted(const GridParams<Real>& g, std::size_t bodies, bool report_mask);
// The cell sort's key of a body: its spilled axes (bits 0-2), the super-cell of its lowest cell above
// them (at most k_block_bits bits: cell_sort_wanted), the parity of that cell in the top 3 bits.
// block_sort's radix sort reads the low half_bits + 3 bits: a super-cell's bodies come out grouped by
// their spilled axes (each group's bodies ascending), so that the loops over a body's cells run the
// same number of steps for long runs of bodies; the parity rides along, and with it the whole control
// byte, so that the bodies' gather into super-cell order reads their spheres alone.
constexpr int k_block_bits = 26;
template <class Real>
std::uint32_t super_cell(const BodyCells& c, const GridParams<Real>& g) {
  return (c.lo[0] >> 1) + g.half[0] * ((c.lo[1] >> 1) + g.half[1] * (c.lo[2] >> 1));
}
template <class Real>
std::uint32_t block_key(const BodyCells& c, const GridParams<Real>& g) {
  return c.spill | (super_cell(c, g) << 3) | ((std::uint32_t(control_bits(c)) & 7u) << (3 + k_block_bits));
}
// Whether pack writes the block keys (pack's `blocks`) where the cell sort runs: unless
// CONTACTGRID_HOST_ENTRIES=cells-via-cells (a measurement switch, the same entries: pack writes each
// body's cells and control byte, block_sort makes the super-cells from the cells and gathers the
// control bytes with the spheres).
bool cell_sort_packs_blocks();
// Whether cell_sort gathers the walk's bodies (EntryBodies) chunk by chunk of super-cells, the eight
// types of a chunk together: unless CONTACTGRID_HOST_CELL_BODIES=types (a measurement switch, the same
// bytes: an even share of the entries a thread, type after type).
bool cell_bodies_by_chunks();
template <class Real>
void block_sort(PackedBodies<Real>& p, const GridParams<Real>& g, int threads, BlockOrder<Real>& out);
// Returns the number of entries; frees `order`.
template <class Real, class Key>
std::uint64_t cell_sort(BlockOrder<Real>& order, const GridParams<Real>& g, int threads, Entries<Key>& out,
                        EntryBodies<Real>& bodies);

// pairs: per sorted entry, the later entries of its cell that the cell rule (test_in_cell) and the
// report mask assign to it; those passing `filter` become candidates (chunks of entries collect
// their pairs, chunk sizes → scan → fill: the same array for any thread count after the entry sort;
// the order stage makes it one after either sort). `fp64` (mixed, with the spheres_touch filter: the
// world doubles, and broad_margin) makes the test fp64's decision (Fp64Touch, core/narrow.hpp).
// `gathered`: the entries' bodies the cell sort wrote (else gathered here from p). Returns the number
// of pairs tested (EngineStats::pair_tests).
template <class Real, class Key>
std::uint64_t find_candidates(const Entries<Key>& e, const PackedBodies<Real>& p,
                              std::span<const std::uint8_t> report, int half_bits, CandidateFilter filter,
                              const NarrowBodies<double>* fp64, int threads, CandidatePairs& out,
                              const std::function<void(std::uint64_t, bool)>* progress = nullptr,
                              const EntryBodies<Real>* gathered = nullptr);
// Whether this CPU runs the float walk's AVX2 steps (CONTACTGRID_HOST_WALK, pairs.cpp): where it does
// not, the walk takes its four-lane steps.
bool walk_avx2_available();

// ---- the cell list (the grid's pair stage for sphere scenes: host/cell_list.cpp, host/cell_walk.cpp) ----
// Each body filed once, under the cell of the lower corner of its box (box_radius of its radius plus
// the inflation), in a grid of its own whose cells are at least as wide as the widest box, bodies
// sorted by cell. Two bodies whose boxes overlap (every pair the sphere test accepts) then have home
// cells at most one apart along each axis, so the walk of each body against the later bodies of its
// own cell and the 13 cells of a half stencil tests every such pair once, reading the bodies in cell
// order. The pairs come out unordered; order_candidates sorts them by (a, b) as any broad phase's.
template <class Real>
struct CellList {
  Real inv_cell = 1;
  Real lo[3] = {0, 0, 0};  // local frame corner of the grid's first inner cell
  // cells per axis, a layer of empty cells on either side included: every cell of a body has its 26
  // neighbours, so the walk needs no bounds
  std::uint32_t dims[3] = {3, 3, 3};
  int key_bits = 1;            // bits of the largest cell key
  Array<std::uint32_t> key;    // cell x + dims[0]·(y + dims[1]·z) of each body, sorted after sort
  Array<std::uint32_t> body;   // input index, alongside
  Array<std::uint32_t> start;  // after sort: the first sorted place of each cell (cells + 1 values)
};

// cell_list_keys (stage entries): the grid (cell edge a little above the widest box) and every body's
// home cell key in input order. Returns false, leaving the grid unused, where Le Grand's cells serve
// better or the list cannot: boxes over a wide range of sizes (the narrowest below a quarter of the
// widest), more than about 8 cells a body (a sparse scene), or a body whose box spans more than two
// cells along an axis (rounding in a grid far wider than its cells); the caller then takes Le Grand's
// cells. sort_cell_list (stage sort): stable radix sort by key, then the cells' first places.
template <class Real>
bool cell_list_keys(const PackedBodies<Real>& p, int threads, CellList<Real>& out);
template <class Real>
void sort_cell_list(CellList<Real>& cl, int threads);

// The pair tests the cell walk would make (pair_estimate.hpp): Σ over bodies of the bodies it walks
// past, the fullest cell as the largest.
template <class Real>
PairEstimate cell_list_estimate(const CellList<Real>& cl, int threads);

// cell_list_candidates (stage pairs): the walk; the pairs passing `filter`'s test (candidates_touch
// filters only, no report mask: the caller checks) into `out`, unordered. Returns the pairs tested.
template <class Real>
std::uint64_t cell_list_candidates(const CellList<Real>& cl, const PackedBodies<Real>& p,
                                   CandidateFilter filter, const NarrowBodies<double>* fp64, int threads,
                                   CandidatePairs& out,
                                   const std::function<void(std::uint64_t, bool)>* progress = nullptr);

// The pair stage's estimate (pair_estimate.hpp) from the sorted entries: Σ over cells of m·(m − 1)/2
// and the fullest cell, in one parallel pass over the keys (each cell counted by the chunk where it
// starts). `bodies`: the call's, for the estimate's per-body figure.
template <class Key>
PairEstimate estimate_pair_tests(const Entries<Key>& e, std::uint64_t bodies, int threads);

// The pair test of the candidate filter (core/narrow.hpp: CellRule, SpheresTouch, mixed's Fp64Touch;
// core/centre_cut.hpp: CentreCut), on input indices, handed to `f`: every broad phase tests with it.
template <class Real, class F>
decltype(auto) with_pair_test(CandidateFilter filter, const PackedBodies<Real>& p,
                              const NarrowBodies<double>* fp64, F&& f) {
  if (!candidates_touch(filter)) return f(CellRule{});
  if (filter == CandidateFilter::centre_cut) return f(CentreCut{p.cut.data(), p.cut_skin});
  if constexpr (std::is_same_v<Real, float>)
    if (fp64 != nullptr && filter == CandidateFilter::spheres_touch)  // mixed: fp64's decision
      return f(Fp64Touch{*fp64, fp64->broad_margin, nullptr});
  return f(SpheresTouch{});
}

// count → scan → fill of the pairs of items [0, n): `visit(i, emit)` emits item i's pairs (a, b),
// a < b, and returns how many pairs it tested. Fixed chunks of items (their number depends on n and
// `per_chunk` alone) collect their pairs once, the chunk sizes are scanned, the chunks copied in order:
// the same array for any thread count. Appends to out.ab; returns the tests.
template <class Visit>
std::uint64_t collect_pairs(std::size_t n, std::size_t per_chunk, int threads, CandidatePairs& out,
                            Visit&& visit) {
  const std::size_t n_chunks = std::max<std::size_t>(1, std::min<std::size_t>(256, n / per_chunk));
  std::vector<std::vector<std::uint64_t>> chunk_pairs(n_chunks);
  const int id_bits = out.id_bits;
  std::uint64_t tests = 0;
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1) reduction(+ : tests) if (n_chunks > 1)
  for (std::size_t c = 0; c < n_chunks; ++c) {
    std::vector<std::uint64_t>& mine = chunk_pairs[c];
    auto emit = [&](std::uint32_t a, std::uint32_t b) { mine.push_back((std::uint64_t(a) << id_bits) | b); };
    for (std::size_t i = n * c / n_chunks, end = n * (c + 1) / n_chunks; i < end; ++i)
      tests += visit(i, emit);
  }
  std::vector<std::uint64_t> chunk_size(n_chunks), chunk_offset;
  for (std::size_t c = 0; c < n_chunks; ++c) chunk_size[c] = chunk_pairs[c].size();
  const std::size_t before = out.ab.size();
  out.ab.resize(before + exclusive_scan_into(chunk_size, chunk_offset));
#pragma omp parallel for num_threads(threads) schedule(static) if (n_chunks > 1)
  for (std::size_t c = 0; c < n_chunks; ++c) {
    std::copy(chunk_pairs[c].begin(), chunk_pairs[c].end(),
              out.ab.begin() + std::ptrdiff_t(before + chunk_offset[c]));
    chunk_pairs[c] = {};
  }
  return tests;
}

// ---- levels (BroadPhase::levels: core/broad.hpp), files host/levels.cpp ----
// level_cells: per body its level (level_of the sphere inflated by p.inflation), its cells in that
// level's grid (of its box, or in centre-cut scenes of its shape's box: cut_cells), control byte and
// entry count. level_entries: (key, body) entries in body order, keys level << key_shift | cell key;
// frees p.cells and p.count. Then sort_entries over the plan's key bits and find_candidates (half
// bits: key_shift − 3) take the pairs within each level; cross_level_candidates appends the pairs of
// two levels, from the smaller body's side (binary search of its cells in the larger level's keys);
// cross_level_estimate, after the sort, bounds those tests (core/broad.hpp cross_level_bound) for
// the pair estimate.
template <class Real>
void level_cells(const LevelParams<Real>& lp, int threads, PackedBodies<Real>& p);
template <class Real, class Key>
std::uint64_t level_entries(PackedBodies<Real>& p, const LevelParams<Real>& lp, int threads,
                            Entries<Key>& out);
template <class Real, class Key>
std::uint64_t cross_level_estimate(const Entries<Key>& e, const PackedBodies<Real>& p,
                                   const LevelParams<Real>& lp, int threads);
template <class Real, class Key>
std::uint64_t cross_level_candidates(const Entries<Key>& e, const PackedBodies<Real>& p,
                                     const LevelParams<Real>& lp, std::span<const std::uint8_t> report,
                                     CandidateFilter filter, const NarrowBodies<double>* fp64, int threads,
                                     CandidatePairs& out);

// ---- sweep (BroadPhase::sweep), host/sweep.cpp ----
// sweep_sort: the bodies by the lower face of their box along `axis` (stable radix sort of its
// orderable bits: ties in input order). sweep_candidates: each body against the later ones whose
// lower face is at most its upper face, those whose boxes overlap (boxes_overlap) tested.
struct SweepOrder {
  std::vector<std::uint32_t> body;  // input index of each sorted place
};
template <class Real>
void sweep_sort(const PackedBodies<Real>& p, int axis, int threads, SweepOrder& out);
// sweep_estimate: the pair estimate of the sweep (pair_estimate.hpp) after sweep_sort: Σ over the
// sorted places of the later boxes that start before the place's box ends (the boxes the sweep passes,
// a bound of its tests), the most of one place as the largest.
template <class Real>
PairEstimate sweep_estimate(const SweepOrder& order, const PackedBodies<Real>& p, int axis, int threads);
template <class Real>
std::uint64_t sweep_candidates(const SweepOrder& order, const PackedBodies<Real>& p, int axis,
                               std::span<const std::uint8_t> report, CandidateFilter filter,
                               const NarrowBodies<double>* fp64, int threads, CandidatePairs& out);

// ---- brute (BroadPhase::brute), host/brute.cpp: every pair (a < b) whose boxes overlap, tested ----
template <class Real>
std::uint64_t brute_candidates(const PackedBodies<Real>& p, std::span<const std::uint8_t> report,
                               CandidateFilter filter, const NarrowBodies<double>* fp64, int threads,
                               CandidatePairs& out);

// order: radix sort of the candidates by (a, b).
void order_candidates(CandidatePairs& c, int threads);

// narrow: narrow_decide() on every candidate (core/narrow.hpp: fp32 from the local floats in
// bodies.spheres, fp64 and mixed from the world doubles); contact rows of the requested fields, world
// frame, in candidate order. When the filter may reject (narrow_may_reject): count → scan → fill
// (accept flags, exclusive scan of chunk counts, fill of the accepted rows); else one row per
// candidate. fp32 rows recomputed in fp64 are added to stats.fp64_rows. `world` (fp64 and mixed, may
// be null): pack's world rows, read in place of bodies.position and bodies.radius (the same doubles)
// where every candidate is a contact.
template <class Real>
void narrow(const CandidatePairs& c, const NarrowBodies<Real>& bodies, Fields fields, int threads,
            Contacts<Real>& out, EngineStats& stats, const Sphere<double>* world = nullptr);

// narrow for scenes with ellipsoids: ShapeDecide (core/shape_narrow.hpp) on every candidate, always
// count → scan → fill (c.filter may reject); the solver's flags are added to stats.narrow_fallbacks
// and stats.narrow_unconverged, fp32's pairs solved in fp64 to stats.fp64_rows (`rows`: the world
// shape rows they are solved from).
template <class Real>
void narrow_shapes(const CandidatePairs& c, const NarrowBodies<Real>& bodies,
                   const std::vector<PackedShape<Real>>& shapes, ShapeRowsView rows,
                   const SolverSettings<Real>& settings, Fields fields, int threads, Contacts<Real>& out,
                   EngineStats& stats);

}  // namespace cg::detail::host
