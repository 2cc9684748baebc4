// Host stage entries: the entry counts scanned per block of bodies → fill (cell key, body) in body order.
#include <algorithm>
#include <vector>

#include "host/stages.hpp"

namespace cg::detail::host {

namespace {

// Entries are filled by fixed blocks of bodies: each block's entry total (from the control bytes:
// 1 << the spilled axes), a scan of the totals, then each block from its offset.
constexpr std::size_t k_block_bodies = 4096;

template <class Real, class Key, class CellsOf>
std::uint64_t fill_blocks(const PackedBodies<Real>& p, const GridParams<Real>& g, int threads,
                          Entries<Key>& out, const CellsOf& cells_of) {
  const std::size_t n = p.ctrl.size();
  const std::size_t n_blocks = (n + k_block_bodies - 1) / k_block_bodies;
  std::vector<std::uint64_t> block_total(n_blocks), block_offset;
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t b = 0; b < n_blocks; ++b) {
    std::uint64_t total = 0;
    for (std::size_t i = b * k_block_bodies, end = std::min(n, i + k_block_bodies); i < end; ++i)
      total += std::uint64_t(1) << popcount3(std::uint32_t(p.ctrl[i]) >> 3);  // entry_count
    block_total[b] = total;
  }
  const std::uint64_t n_entries = exclusive_scan_into(block_total, block_offset);
  out.keys.resize(n_entries);
  out.body.resize(n_entries);
  Key* keys = out.keys.data();
  std::uint32_t* body = out.body.data();
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t b = 0; b < n_blocks; ++b) {
    std::uint64_t at = block_offset[b];
    for (std::size_t i = b * k_block_bodies, end = std::min(n, i + k_block_bodies); i < end; ++i) {
      const BodyCells cells = cells_of(i);
      const std::uint32_t count = entry_count(cells);
      for (std::uint32_t m = 0; m < count; ++m, ++at) {
        keys[at] = body_cell_key<Key>(cells, m, g);
        body[at] = static_cast<std::uint32_t>(i);
      }
    }
  }
  return n_entries;
}

}  // namespace

template <class Real, class Key>
std::uint64_t fill_entries(PackedBodies<Real>& p, const GridParams<Real>& g, int threads, Entries<Key>& out) {
  const BodyCells* cells = p.cells.data();
  const std::uint64_t n_entries = fill_blocks(p, g, threads, out, [&](std::size_t i) { return cells[i]; });
  p.cells = {};
  p.count = {};
  return n_entries;
}

template std::uint64_t fill_entries(PackedBodies<float>&, const GridParams<float>&, int,
                                    Entries<std::uint32_t>&);
template std::uint64_t fill_entries(PackedBodies<float>&, const GridParams<float>&, int,
                                    Entries<std::uint64_t>&);
template std::uint64_t fill_entries(PackedBodies<double>&, const GridParams<double>&, int,
                                    Entries<std::uint32_t>&);
template std::uint64_t fill_entries(PackedBodies<double>&, const GridParams<double>&, int,
                                    Entries<std::uint64_t>&);

}  // namespace cg::detail::host
