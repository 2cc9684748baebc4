// Host stage narrow for scenes with ellipsoids (see stages.hpp: narrow_shapes): ShapeDecide
// (core/shape_narrow.hpp) on every candidate, count → scan → fill. Sphere-only scenes never come here
// (narrow.cpp). Kept apart from narrow.cpp so that the sphere path is untouched; rows go through the one
// row store (store_row, core/contact_fields.hpp).
#include <algorithm>

#include "host/stages.hpp"

namespace cg::detail::host {
namespace {

// count → scan → fill with ShapeDecide over chunks of candidates; the rows (candidate order, chunk
// offsets from the scan) do not depend on the chunking or the thread count. A candidate costs up to
// ~100 sphere tests, and unevenly: small chunks (>= 64 candidates, up to 8192) handed out dynamically.
// The rows of the accepted candidates are kept per chunk by the count pass, built as the device builds
// them (triage, settle for the candidates it leaves, solve for the ones still hard, row_from the
// minimiser: the same bits).
struct NarrowCounts {
  NarrowFlags flags;
  std::uint64_t unsettled = 0, hard = 0, evaluations = 0;
};

template <class Real>
NarrowCounts narrow_compact(const CandidatePairs& c, const ShapeDecide<Real>& decide, bool full, int nt,
                            Contacts<Real>& out) {
  const std::size_t n_cand = c.size();
  const std::size_t n_chunks = std::max<std::size_t>(1, std::min<std::size_t>(8192, n_cand / 64));
  std::vector<std::uint64_t> chunk_count(n_chunks, 0), chunk_offset;
  std::vector<NarrowFlags> chunk_flags(n_chunks);
  std::vector<std::uint64_t> chunk_hard(n_chunks, 0), chunk_unsettled(n_chunks, 0);
  std::vector<std::uint8_t> accept(n_cand);
  // count: an accept flag per candidate, the accepted total and the solver's flags per chunk
  std::vector<std::vector<ContactRow<Real>>> chunk_rows(n_chunks);
  auto count_chunk = [&](std::size_t ch) {
    std::uint64_t count = 0;
    NarrowFlags flags;
    std::uint64_t hard = 0, unsettled = 0;
    for (std::size_t k = n_cand * ch / n_chunks, end = n_cand * (ch + 1) / n_chunks; k < end; ++k) {
      // the device's passes, in one: triage, settle where the cheap certificates did not settle it,
      // the whole solve where no certificate did, the row from the minimiser
      const std::uint32_t a = c.a(k), b = c.b(k);
      Vec3<Real> n{};
      FirstStart<Real> first;  // a hard pair's first start, kept by triage for settle
      auto verdict = decide.triage(a, b, flags, n, &first);
      if (verdict == ShapeDecide<Real>::Verdict::hard) {
        ++unsettled;
        verdict = decide.settle(a, b, flags, n, &first);
      }
      if (verdict == ShapeDecide<Real>::Verdict::hard) {
        ++hard;
        verdict = decide.solve(a, b, flags, n) ? ShapeDecide<Real>::Verdict::accept
                                               : ShapeDecide<Real>::Verdict::reject;
      }
      accept[k] = verdict == ShapeDecide<Real>::Verdict::accept;
      if (accept[k]) chunk_rows[ch].push_back(decide.row_from(a, b, n, full));
      count += accept[k];
    }
    chunk_count[ch] = count;
    chunk_flags[ch] = flags;
    chunk_hard[ch] = hard;
    chunk_unsettled[ch] = unsettled;
  };
  ContactColumns<Real, Ptr> rows;
  auto fill_chunk = [&](std::size_t ch) {
    std::size_t w = chunk_offset[ch], i = 0;
    for (std::size_t k = n_cand * ch / n_chunks, end = n_cand * (ch + 1) / n_chunks; k < end; ++k) {
      if (!accept[k]) continue;
      ContactRow<Real>& row = chunk_rows[ch][i++];
      row.id_a = c.a(k);
      row.id_b = c.b(k);
      store_row(rows, w++, row, full);
    }
  };
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1) if (n_chunks > 1)
  for (std::size_t ch = 0; ch < n_chunks; ++ch) count_chunk(ch);
  // scan → fill
  const std::uint64_t n_rows = exclusive_scan_into(chunk_count, chunk_offset);
  out.resize(n_rows, full);
  rows = columns_of(out);
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1) if (n_chunks > 1)
  for (std::size_t ch = 0; ch < n_chunks; ++ch) fill_chunk(ch);
  NarrowCounts total;
  std::uint64_t evaluations = 0;  // the sum over chunks may pass 2^32
  for (std::size_t ch = 0; ch < n_chunks; ++ch) {
    evaluations += chunk_flags[ch].evaluations;
    total.flags.add(chunk_flags[ch]);
    total.hard += chunk_hard[ch];
    total.unsettled += chunk_unsettled[ch];
  }
  total.evaluations = evaluations;
  return total;
}

}  // namespace

template <class Real>
void narrow_shapes(const CandidatePairs& c, const NarrowBodies<Real>& bodies,
                   const std::vector<PackedShape<Real>>& shapes, ShapeRowsView rows,
                   const SolverSettings<Real>& settings, Fields fields, int nt, Contacts<Real>& out,
                   EngineStats& stats) {
  const NarrowCounts f = narrow_compact(
      c, ShapeDecide<Real>{bodies, shapes.data(), settings, rows, c.filter == CandidateFilter::centre_cut},
      fields == Fields::full, nt, out);
  stats.narrow_fallbacks += f.flags.fallbacks;
  stats.narrow_unconverged += f.flags.unconverged;
  stats.fp64_rows += f.flags.fp64_rows;
  stats.narrow_unsettled += f.unsettled;
  stats.narrow_hard += f.hard;
  stats.narrow_solver_runs += f.flags.solver_runs;
  stats.narrow_evaluations += f.evaluations;
  stats.narrow_max_evaluations =
      std::max<std::uint64_t>(stats.narrow_max_evaluations, f.flags.max_evaluations);
}

template void narrow_shapes(const CandidatePairs&, const NarrowBodies<float>&,
                            const std::vector<PackedShape<float>>&, ShapeRowsView,
                            const SolverSettings<float>&, Fields, int, Contacts<float>&, EngineStats&);
template void narrow_shapes(const CandidatePairs&, const NarrowBodies<double>&,
                            const std::vector<PackedShape<double>>&, ShapeRowsView,
                            const SolverSettings<double>&, Fields, int, Contacts<double>&, EngineStats&);

}  // namespace cg::detail::host
