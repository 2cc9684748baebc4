// Host stage narrow for scenes with ellipsoids (see stages.hpp: narrow_shapes): ShapeDecide
// (core/shape_narrow.hpp) on every candidate, count → scan → fill. Sphere-only scenes never come here
// (narrow.cpp). Kept apart from narrow.cpp so that the sphere path is untouched; store_row mirrors
// narrow.cpp's write_row (the row store).
#include <algorithm>

#include "host/stages.hpp"

namespace cg::detail::host {
namespace {

template <class Real>
void store_row(Contacts<Real>& out, std::size_t k, std::uint32_t a, std::uint32_t b,
               const ContactRow<Real>& row, bool full) {
  out.id_a[k] = a;
  out.id_b[k] = b;
  out.position_on_a[k] = row.position_on_a;
  out.position_on_b[k] = row.position_on_b;
  out.normal_on_b[k] = row.normal_on_b;
  out.distance[k] = row.distance;
  if (full) {
    out.local_point_a[k] = row.local_point_a;
    out.local_point_b[k] = row.local_point_b;
    out.lateral_friction_dir1[k] = row.lateral_friction_dir1;
    out.lateral_friction_dir2[k] = row.lateral_friction_dir2;
  }
}

// count → scan → fill with ShapeDecide over chunks of candidates; the rows (candidate order, chunk
// offsets from the scan) do not depend on the chunking or the thread count. A candidate costs up to
// ~100 sphere tests, and unevenly: small chunks (>= 64 candidates, up to 8192) handed out dynamically.
// The rows of the accepted candidates are kept per chunk by the count pass (accept_row: one solve per
// contact; the device solves again in its fill pass, ShapeDecide::row, the same bits).
template <class Real>
NarrowFlags narrow_compact(const CandidatePairs& c, const ShapeDecide<Real>& decide, bool full, int nt,
                           Contacts<Real>& out) {
  const std::size_t n_cand = c.size();
  const std::size_t n_chunks = std::max<std::size_t>(1, std::min<std::size_t>(8192, n_cand / 64));
  std::vector<std::uint64_t> chunk_count(n_chunks, 0), chunk_offset;
  std::vector<NarrowFlags> chunk_flags(n_chunks);
  std::vector<std::uint8_t> accept(n_cand);
  // count: an accept flag per candidate, the accepted total and the solver's flags per chunk
  std::vector<std::vector<ContactRow<Real>>> chunk_rows(n_chunks);
  auto count_chunk = [&](std::size_t ch) {
    std::uint64_t count = 0;
    NarrowFlags flags;
    for (std::size_t k = n_cand * ch / n_chunks, end = n_cand * (ch + 1) / n_chunks; k < end; ++k) {
      ContactRow<Real> row;
      accept[k] = decide.accept_row(c.a(k), c.b(k), full, flags, row);
      if (accept[k]) chunk_rows[ch].push_back(row);
      count += accept[k];
    }
    chunk_count[ch] = count;
    chunk_flags[ch] = flags;
  };
  auto fill_chunk = [&](std::size_t ch) {
    std::size_t w = chunk_offset[ch], i = 0;
    for (std::size_t k = n_cand * ch / n_chunks, end = n_cand * (ch + 1) / n_chunks; k < end; ++k) {
      if (!accept[k]) continue;
      store_row(out, w++, c.a(k), c.b(k), chunk_rows[ch][i++], full);
    }
  };
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1) if (n_chunks > 1)
  for (std::size_t ch = 0; ch < n_chunks; ++ch) count_chunk(ch);
  // scan → fill
  const std::uint64_t n_rows = exclusive_scan_into(chunk_count, chunk_offset);
  out.resize(n_rows, full);
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1) if (n_chunks > 1)
  for (std::size_t ch = 0; ch < n_chunks; ++ch) fill_chunk(ch);
  NarrowFlags total;
  for (const NarrowFlags& f : chunk_flags) {
    total.fallbacks += f.fallbacks;
    total.unconverged += f.unconverged;
  }
  return total;
}

}  // namespace

template <class Real>
void narrow_shapes(const CandidatePairs& c, const std::vector<Sphere<Real>>& spheres,
                   const std::vector<PackedShape<Real>>& shapes, const Vec3<double>& origin,
                   const SolverSettings<Real>& settings, Fields fields, int nt, Contacts<Real>& out,
                   EngineStats& stats) {
  const NarrowFlags f = narrow_compact(c, ShapeDecide<Real>{spheres.data(), shapes.data(), origin, settings},
                                       fields == Fields::full, nt, out);
  stats.narrow_fallbacks += f.fallbacks;
  stats.narrow_unconverged += f.unconverged;
}

template void narrow_shapes(const CandidatePairs&, const std::vector<Sphere<float>>&,
                            const std::vector<PackedShape<float>>&, const Vec3<double>&,
                            const SolverSettings<float>&, Fields, int, Contacts<float>&, EngineStats&);
template void narrow_shapes(const CandidatePairs&, const std::vector<Sphere<double>>&,
                            const std::vector<PackedShape<double>>&, const Vec3<double>&,
                            const SolverSettings<double>&, Fields, int, Contacts<double>&, EngineStats&);

}  // namespace cg::detail::host
