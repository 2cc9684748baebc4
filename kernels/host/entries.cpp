// Host stage entries: exclusive scan of the entry counts → fill (cell key, body) in body order.
#include "host/stages.hpp"

namespace cg::detail::host {

template <class Real, class Key>
std::uint64_t fill_entries(PackedBodies<Real>& p, const GridParams<Real>& g, int threads, Entries<Key>& out) {
  const std::size_t n = p.cells.size();
  Array<std::uint64_t> offset;
  const std::uint64_t n_entries = exclusive_scan_into(p.count, offset);
  out.keys.resize(n_entries);
  out.body.resize(n_entries);
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    for (std::uint32_t m = 0; m < p.count[i]; ++m) {
      out.keys[offset[i] + m] = body_cell_key<Key>(p.cells[i], m, g);
      out.body[offset[i] + m] = static_cast<std::uint32_t>(i);
    }
  }
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
