#pragma once
// The CPU backend's stages, one file each (pack.cpp, entries.cpp, sort.cpp, pairs.cpp, order.cpp,
// narrow.cpp), sequenced by host_backend.cpp. All memory is HOST memory; `threads` OpenMP threads
// (> 0). Every decision and value comes from the CG_HD functions of kernels/core/, in the order the
// CUDA kernels use, so this backend is the oracle of the CUDA one.
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "core/centre_cut.hpp"
#include "core/grid.hpp"
#include "core/narrow.hpp"
#include "core/shape_narrow.hpp"
#include "core/skin.hpp"
#include "engine.hpp"

namespace cg::detail::host {

// Below this many items a loop runs on the calling thread: waking a team costs more than it saves.
constexpr std::size_t k_parallel_min = 32768;

// Exclusive scan of `counts` into `offsets` (size + 1 values, the last the total); returns the total.
template <class T, class Acc>
Acc exclusive_scan_into(const std::vector<T>& counts, std::vector<Acc>& offsets) {
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
  std::vector<Sphere<Real>> spheres;  // local frame: Real(world - origin)
  Real inflation = 0;                 // added to every radius by the pair stage (cells, test)
  std::vector<BodyCells> cells;       // freed by fill_entries
  std::vector<std::uint8_t> ctrl;     // control_bits
  std::vector<std::uint32_t> count;   // entry_count; freed by fill_entries
  std::vector<CutShape> cut;          // CandidateFilter::centre_cut: cut_shape() of every body
};

// (cell key, body) entries; body-ascending after fill_entries, key-ascending (stable) after sort.
template <class Key>
struct Entries {
  std::vector<Key> keys;
  std::vector<std::uint32_t> body;
  std::size_t size() const { return keys.size(); }
};

// Candidate pairs of local indices a < b, packed as a << id_bits | b: a plain (a, b) array, ascending
// after order_candidates (so a list can be kept across calls and handed to narrow again).
struct CandidatePairs {
  std::vector<std::uint64_t> ab;
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
};

// skin: what moved since `kept` was built (same body count): max |x − x_ref|, max radius growth,
// whether the report mask changed. keep_candidates: `c` (moved, not copied: the narrow stage then
// reads the kept list) and the state of `bodies` into `kept`.
Motion measure_motion(const BodiesView& bodies, const KeptCandidates& kept, int threads);
void keep_candidates(const BodiesView& bodies, CandidatePairs&& c, KeptCandidates& kept);

// pack: world (double) → local Real spheres; per body its cells (of the sphere inflated by
// `inflation`, 0 without a skin), control byte and entry count. cells_too false: the spheres only
// (the reuse of kept candidates needs no grid).
template <class Real>
void pack(const BodiesView& bodies, const Vec3<double>& origin, const GridParams<Real>& g, Real inflation,
          bool cells_too, int threads, PackedBodies<Real>& out);

// pack_shapes (scenes with ellipsoids): pack_shape() of every body, input order.
template <class Real>
void pack_shapes(const BodiesView& bodies, int threads, std::vector<PackedShape<Real>>& out);

// cut_shapes (CandidateFilter::centre_cut): cut_shape() of every packed shape, input order.
template <class Packed>
void cut_shapes(const std::vector<PackedShape<Packed>>& shapes, int threads, std::vector<CutShape>& out);

// shape_cells (CandidateFilter::centre_cut, after cut_shapes; pack made the spheres only): the cells,
// control byte and entry count of each body from the box of its shape instead of its bounding sphere
// (core/centre_cut.hpp: cut_cells).
template <class Real>
void shape_cells(const GridParams<Real>& g, int threads, PackedBodies<Real>& bodies);

// entries: exclusive scan of the entry counts → fill (cell key, body) in body order. Returns the
// number of entries; frees p.cells and p.count.
template <class Real, class Key>
std::uint64_t fill_entries(PackedBodies<Real>& p, const GridParams<Real>& g, int threads, Entries<Key>& out);

// sort: stable radix sort of the entries by cell key over key_bits bits.
template <class Key>
void sort_entries(Entries<Key>& e, int key_bits, int threads);

// pairs: per sorted entry, the later entries of its cell that the cell rule (test_in_cell) and the
// report mask assign to it; those passing `filter` become candidates (chunks of entries collect
// their pairs, chunk sizes → scan → fill: the same array for any thread count). `fp64` (mixed, with
// the spheres_touch filter: the world doubles, and broad_margin) makes the test fp64's decision
// (Fp64Touch, core/narrow.hpp). Returns the number of pairs tested (EngineStats::pair_tests).
template <class Real, class Key>
std::uint64_t find_candidates(const Entries<Key>& e, const PackedBodies<Real>& p,
                              std::span<const std::uint8_t> report, int half_bits, CandidateFilter filter,
                              const NarrowBodies<double>* fp64, int threads, CandidatePairs& out,
                              const std::function<void(std::uint64_t, bool)>* progress = nullptr);

// The pair stage's estimate (pair_estimate.hpp) from the sorted entries: Σ over cells of m·(m − 1)/2
// and the fullest cell, in one parallel pass over the keys (each cell counted by the chunk where it
// starts). `bodies`: the call's, for the estimate's per-body figure.
template <class Key>
PairEstimate estimate_pair_tests(const Entries<Key>& e, std::uint64_t bodies, int threads);

// order: radix sort of the candidates by (a, b).
void order_candidates(CandidatePairs& c, int threads);

// narrow: narrow_decide() on every candidate (core/narrow.hpp: fp32 from the local floats in
// bodies.spheres, fp64 and mixed from the world doubles); contact rows of the requested fields, world
// frame, in candidate order. When the filter may reject (narrow_may_reject): count → scan → fill
// (accept flags, exclusive scan of chunk counts, fill of the accepted rows); else one row per
// candidate. fp32 rows recomputed in fp64 are added to stats.fp64_rows.
template <class Real>
void narrow(const CandidatePairs& c, const NarrowBodies<Real>& bodies, Fields fields, int threads,
            Contacts<Real>& out, EngineStats& stats);

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
