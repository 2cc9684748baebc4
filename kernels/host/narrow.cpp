// Host stage narrow: narrow_decide() on the ordered candidates; rows of the accepted ones (see
// stages.hpp). Count → scan → fill when the candidate filter may reject, else one row per candidate.
#include <algorithm>
#include <cstdlib>
#include <string_view>
#include <type_traits>

#include "host/stages.hpp"

namespace cg::detail::host {
namespace {

// The narrow stage's reads of body i, asked for ahead: the candidates ascend in a, so b's reads are
// random and each would stall a row on a cache miss (fp32: its local sphere; fp64 and mixed: the world
// centre, which may straddle two cache lines, and radius).
constexpr std::size_t k_prefetch_rows = 16;

// CONTACTGRID_HOST_ROWS=whole: basic rows built as a whole row and stored (the generic store_row).
const bool g_basic_rows_direct = [] {
  const char* k = std::getenv("CONTACTGRID_HOST_ROWS");
  return !(k != nullptr && std::string_view(k) == "whole");
}();
template <class Real>
void prefetch_body(const NarrowBodies<Real>& w, std::uint32_t i) {
  if constexpr (std::is_same_v<Real, float>) {
    __builtin_prefetch(w.spheres + i);
  } else {
    __builtin_prefetch(w.position + 3 * std::size_t(i));
    __builtin_prefetch(w.position + 3 * std::size_t(i) + 2);
    __builtin_prefetch(w.radius + i);
  }
}

// Row k of `rows`: the decided pair (a, b) with its row (the one row store: store_row).
template <class Real>
void write_row(const ContactColumns<Real, Ptr>& rows, std::size_t k, std::uint32_t a, std::uint32_t b,
               ContactRow<Real> row, bool full) {
  row.id_a = a;
  row.id_b = b;
  store_row(rows, k, row, full);
}

// narrow_decide's fp64 and mixed branch (core/narrow.hpp) on pack's world rows (the same doubles as
// the input's position and radius arrays, one cache line a body): touch_fp64 on the frame-local
// doubles, the row from the world doubles.
template <bool kFull>
ContactRow<double> world_rows_decide(const Sphere<double>* world, const Vec3<double>& origin, std::uint32_t a,
                                     std::uint32_t b) {
  const Sphere<double> sa = world[a], sb = world[b];
  ContactRow<double> row{};
  const Sphere<double> la{sa.x - origin.x, sa.y - origin.y, sa.z - origin.z, sa.r};
  const Sphere<double> lb{sb.x - origin.x, sb.y - origin.y, sb.z - origin.z, sb.r};
  if (spheres_touch(la, lb)) row = world_sphere_row(sa, sb, kFull);
  return row;
}

// One row per candidate (every candidate is a contact), rows [lo, hi). kFull: the full fields, a
// constant here so that a basic row's inlined core functions drop the full fields' work (their zeroed
// members, the friction basis) and the row's copies. `world` (fp64, mixed; may be null): pack's world
// rows, read in place of the input's arrays.
template <bool kFull, class Real>
std::uint64_t one_row_per_candidate(const CandidatePairs& c, const NarrowBodies<Real>& bodies,
                                    const NarrowBodies<Real>& one_row, const Sphere<double>* world,
                                    const ContactColumns<Real, Ptr>& rows, std::size_t lo, std::size_t hi) {
  const std::size_t n_cand = c.size();
  NarrowFlags flags;
  if constexpr (std::is_same_v<Real, double>) {
    if (world != nullptr && !kFull && g_basic_rows_direct) {
      // basic fields: world_sphere_row's four fields (sphere_sphere_contact's geometry) stored into
      // the columns as computed, without the zeroed whole row and its copies (a contact's hottest
      // work here); a candidate that does not touch stores the zero row, as world_rows_decide
      for (std::size_t k = lo; k < hi; ++k) {
        if (k + k_prefetch_rows < n_cand) __builtin_prefetch(world + c.b(k + k_prefetch_rows));
        const std::uint32_t a = c.a(k), b = c.b(k);
        const Sphere<double> sa = world[a], sb = world[b];
        const Vec3<double>& o = bodies.origin;
        const Sphere<double> la{sa.x - o.x, sa.y - o.y, sa.z - o.z, sa.r};
        const Sphere<double> lb{sb.x - o.x, sb.y - o.y, sb.z - o.z, sb.r};
        rows.id_a[k] = a;
        rows.id_b[k] = b;
        if (spheres_touch(la, lb)) {
          const ContactGeometry<double> g = sphere_sphere_contact(sa, sb);
          rows.position_on_a[k] = g.position_on_a;
          rows.position_on_b[k] = g.position_on_b;
          rows.normal_on_b[k] = g.normal_on_b;
          rows.distance[k] = g.distance;
        } else {
          rows.position_on_a[k] = rows.position_on_b[k] = rows.normal_on_b[k] = Vec3<double>{0, 0, 0};
          rows.distance[k] = 0;
        }
      }
      return 0;
    }
    if (world != nullptr) {
      for (std::size_t k = lo; k < hi; ++k) {
        if (k + k_prefetch_rows < n_cand) __builtin_prefetch(world + c.b(k + k_prefetch_rows));
        const std::uint32_t a = c.a(k), b = c.b(k);
        write_row(rows, k, a, b, world_rows_decide<kFull>(world, bodies.origin, a, b), kFull);
      }
      return 0;
    }
  }
  for (std::size_t k = lo; k < hi; ++k) {
    if (k + k_prefetch_rows < n_cand) prefetch_body(bodies, c.b(k + k_prefetch_rows));
    const std::uint32_t a = c.a(k), b = c.b(k);
    write_row(rows, k, a, b, narrow_decide(one_row, a, b, kFull, flags).row, kFull);
  }
  return flags.fp64_rows;
}

}  // namespace

template <class Real>
void narrow(const CandidatePairs& c, const NarrowBodies<Real>& bodies, Fields fields, int nt,
            Contacts<Real>& out, EngineStats& stats, const Sphere<double>* world) {
  const bool full = fields == Fields::full;
  const std::size_t n_cand = c.size();
  std::uint64_t fp64_rows = 0;
  if (!narrow_may_reject(c.filter)) {     // every candidate is a contact: no scan
    NarrowBodies<Real> one_row = bodies;  // (mixed's floats would only add reads, as on the device)
    one_row.broad = nullptr;
    out.resize(n_cand, full);
    const ContactColumns<Real, Ptr> rows = columns_of(out);
    const std::size_t n_chunks = std::max<std::size_t>(1, std::min<std::size_t>(256, n_cand / 16384));
#pragma omp parallel for num_threads(nt) schedule(static) reduction(+ : fp64_rows) if (n_chunks > 1)
    for (std::size_t ch = 0; ch < n_chunks; ++ch) {
      const std::size_t lo = n_cand * ch / n_chunks, hi = n_cand * (ch + 1) / n_chunks;
      fp64_rows += full ? one_row_per_candidate<true>(c, bodies, one_row, world, rows, lo, hi)
                        : one_row_per_candidate<false>(c, bodies, one_row, world, rows, lo, hi);
    }
    stats.fp64_rows += fp64_rows;
    return;
  }
  // count: an accept flag per candidate and the accepted total per fixed chunk of candidates (the
  // chunking depends only on the candidate count: the rows are the same for any thread count)
  const SphereDecide<Real> decide{bodies};
  const std::size_t n_chunks = std::max<std::size_t>(1, std::min<std::size_t>(256, n_cand / 16384));
  std::vector<std::uint64_t> chunk_count(n_chunks, 0), chunk_offset;
  Array<std::uint8_t> accept(n_cand);
#pragma omp parallel for num_threads(nt) schedule(static) reduction(+ : fp64_rows) if (n_chunks > 1)
  for (std::size_t ch = 0; ch < n_chunks; ++ch) {
    std::uint64_t count = 0;
    NarrowFlags flags;
    for (std::size_t k = n_cand * ch / n_chunks, end = n_cand * (ch + 1) / n_chunks; k < end; ++k) {
      if (k + k_prefetch_rows < n_cand) prefetch_body(bodies, c.b(k + k_prefetch_rows));
      accept[k] = decide.accept(c.a(k), c.b(k), flags);
      count += accept[k];
    }
    chunk_count[ch] = count;
    fp64_rows += flags.fp64_rows;
  }
  stats.fp64_rows += fp64_rows;
  // scan → fill
  const std::uint64_t n_rows = exclusive_scan_into(chunk_count, chunk_offset);
  out.resize(n_rows, full);
  const ContactColumns<Real, Ptr> rows = columns_of(out);
#pragma omp parallel for num_threads(nt) schedule(static) if (n_chunks > 1)
  for (std::size_t ch = 0; ch < n_chunks; ++ch) {
    std::size_t w = chunk_offset[ch];
    for (std::size_t k = n_cand * ch / n_chunks, end = n_cand * (ch + 1) / n_chunks; k < end; ++k) {
      if (!accept[k]) continue;
      const std::uint32_t a = c.a(k), b = c.b(k);
      write_row(rows, w++, a, b, decide.row(a, b, full), full);
    }
  }
}

template void narrow(const CandidatePairs&, const NarrowBodies<float>&, Fields, int, Contacts<float>&,
                     EngineStats&, const Sphere<double>*);
template void narrow(const CandidatePairs&, const NarrowBodies<double>&, Fields, int, Contacts<double>&,
                     EngineStats&, const Sphere<double>*);

}  // namespace cg::detail::host
