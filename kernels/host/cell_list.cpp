// Host stages entries and sort of the cell list: the grid of the cell walk, each body's home cell key,
// the bodies sorted by it (see stages.hpp).
#include <algorithm>
#include <cmath>
#include <limits>

#include "backend.hpp"
#include "host/radix_sort.hpp"
#include "host/stages.hpp"

namespace cg::detail::host {
namespace {

// floor((v − lo) · inv) clamped to [0, dims − 1]: monotone in v, so boxes that overlap share a cell.
template <class Real>
std::uint32_t list_coord(Real v, Real lo, Real inv, std::uint32_t dims) {
  const Real f = (v - lo) * inv;
  if (!(f >= Real(0))) return 0;
  if (f >= static_cast<Real>(dims - 1)) return dims - 1;
  return static_cast<std::uint32_t>(f);
}

// The bodies' extent: the lowest and highest box faces and the widest and narrowest box radius.
template <class Real>
struct Extent {
  Real lo[3], hi[3], box = 0, box_min = 0;
};

template <class Real>
Extent<Real> extent_of(const PackedBodies<Real>& p, int threads) {
  const std::size_t n = p.spheres.size();
  constexpr Real inf = std::numeric_limits<Real>::infinity();
  Real lo0 = inf, lo1 = inf, lo2 = inf, hi0 = -inf, hi1 = -inf, hi2 = -inf, box = 0, box_min = inf;
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min) \
    reduction(min                                                                      \
              : lo0, lo1, lo2, box_min) reduction(max                                  \
                                                  : hi0, hi1, hi2, box)
  for (std::size_t i = 0; i < n; ++i) {
    const Sphere<Real> s = p.spheres[i];
    const Real e = box_radius(s.r + p.inflation);
    lo0 = std::min(lo0, s.x - e), lo1 = std::min(lo1, s.y - e), lo2 = std::min(lo2, s.z - e);
    hi0 = std::max(hi0, s.x + e), hi1 = std::max(hi1, s.y + e), hi2 = std::max(hi2, s.z + e);
    box = std::max(box, e);
    box_min = std::min(box_min, e);
  }
  return {{lo0, lo1, lo2}, {hi0, hi1, hi2}, box, box_min};
}

}  // namespace

template <class Real>
bool cell_list_keys(const PackedBodies<Real>& p, int threads, CellList<Real>& out) {
  const std::size_t n = p.spheres.size();
  if (n == 0) return false;
  const Extent<Real> ext = extent_of(p, threads);
  // The list walks 13.5 cells a body, each as wide as the widest box: where the boxes differ widely in
  // size (the narrowest below a quarter of the widest) Le Grand's cells, each body in those its box
  // covers, test fewer pairs.
  if (!(ext.box_min >= ext.box / Real(4))) return false;
  // The edge: the widest box's diameter and 1 % (the rounding of the faces and of the product by
  // 1/edge stays far below it while the grid has fewer than about 2^16 cells along an axis; the check
  // below catches the rest). A scene whose cells, a layer of empty ones about them included, would
  // outnumber 8 a body (sparse: the cells' first places hold a value a cell) takes Le Grand's cells.
  const double edge = 2.0 * double(ext.box) * 1.01;
  if (!(edge > 0) || !std::isfinite(edge)) return false;
  const double span[3] = {double(ext.hi[0]) - double(ext.lo[0]), double(ext.hi[1]) - double(ext.lo[1]),
                          double(ext.hi[2]) - double(ext.lo[2])};
  double padded_cells = 1;
  for (double sp : span) padded_cells *= std::max(1.0, std::ceil(sp / edge)) + 2.0;
  if (!(padded_cells <= std::min(double(std::uint32_t(1) << 31), 8.0 * double(n) + double(1 << 16))))
    return false;
  out.inv_cell = static_cast<Real>(1.0 / edge);
  std::uint32_t inner[3];
  std::uint64_t cells = 1;
  for (int k = 0; k < 3; ++k) {
    out.lo[k] = ext.lo[k];
    inner[k] = static_cast<std::uint32_t>(std::max(1.0, std::ceil(span[k] / edge)));
    out.dims[k] = inner[k] + 2;
    cells *= out.dims[k];
  }
  out.key_bits = std::max(1, bits_for(cells));
  out.key.resize(n);
  out.body.resize(n);
  const std::uint32_t dx = out.dims[0], dy = out.dims[1];
  const Real inv = out.inv_cell, l0 = out.lo[0], l1 = out.lo[1], l2 = out.lo[2];
  int spans_three = 0;
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min) \
    reduction(|                                                                        \
              : spans_three)
  for (std::size_t i = 0; i < n; ++i) {
    const Sphere<Real> s = p.spheres[i];
    const Real e = box_radius(s.r + p.inflation);
    const std::uint32_t x = list_coord(s.x - e, l0, inv, inner[0]),
                        y = list_coord(s.y - e, l1, inv, inner[1]),
                        z = list_coord(s.z - e, l2, inv, inner[2]);
    spans_three |= int(list_coord(s.x + e, l0, inv, inner[0]) > x + 1) |
                   int(list_coord(s.y + e, l1, inv, inner[1]) > y + 1) |
                   int(list_coord(s.z + e, l2, inv, inner[2]) > z + 1);
    out.key[i] = (x + 1) + dx * ((y + 1) + dy * (z + 1));  // the layer of empty cells first
    out.body[i] = static_cast<std::uint32_t>(i);
  }
  return spans_three == 0;
}

template <class Real>
void sort_cell_list(CellList<Real>& cl, int threads) {
  radix_sort(cl.key, cl.body, cl.key_bits, threads);
  // start[c]: the first sorted place of cell c or of a later cell. Chunks of cells, each from the
  // places of its cells: their counts, then an exclusive scan from the chunk's first place (no branch
  // a cell or a place).
  const std::size_t n = cl.key.size();
  const std::size_t cells = std::size_t(cl.dims[0]) * cl.dims[1] * cl.dims[2];
  cl.start.resize(cells + 1);
  const std::uint32_t* key = cl.key.data();
  std::uint32_t* start = cl.start.data();
  const std::size_t n_chunks = std::max<std::size_t>(1, std::min<std::size_t>(64, cells / 65536));
#pragma omp parallel for num_threads(threads) schedule(static) if (n_chunks > 1)
  for (std::size_t ch = 0; ch < n_chunks; ++ch) {
    const std::size_t c_lo = cells * ch / n_chunks, c_hi = cells * (ch + 1) / n_chunks;
    const std::size_t p_lo = std::size_t(std::lower_bound(key, key + n, std::uint64_t(c_lo)) - key);
    const std::size_t p_hi = std::size_t(std::lower_bound(key, key + n, std::uint64_t(c_hi)) - key);
    std::fill(start + c_lo, start + c_hi, 0u);
    for (std::size_t p = p_lo; p < p_hi; ++p) ++start[key[p]];
    std::uint32_t at = static_cast<std::uint32_t>(p_lo);
    for (std::size_t c = c_lo; c < c_hi; ++c) {
      const std::uint32_t count = start[c];
      start[c] = at;
      at += count;
    }
  }
  start[cells] = static_cast<std::uint32_t>(n);
}

template bool cell_list_keys(const PackedBodies<float>&, int, CellList<float>&);
template bool cell_list_keys(const PackedBodies<double>&, int, CellList<double>&);
template void sort_cell_list(CellList<float>&, int);
template void sort_cell_list(CellList<double>&, int);

}  // namespace cg::detail::host
