// Host stage entries: the (cell key, body) entries in body order (the entry counts scanned per block
// of bodies, then a fill), or, opt-in, grouped by the top digit of their key (a counting pass, then
// each entry straight to its group: the first pass of the sort, see below).
#include <omp.h>

#include <algorithm>
#include <cstdlib>
#include <string_view>
#include <vector>

#include "host/stages.hpp"

namespace cg::detail::host {

namespace {

// Entries are filled by fixed blocks of bodies: each block's entry total (from the control bytes:
// 1 << the spilled axes), a scan of the totals, then each block from its offset.
constexpr std::size_t k_block_bodies = 4096;
// The grouped fill makes its entries a block of this many bodies at a time (up to 8 entries a body).
constexpr std::size_t k_digit_block = 256;

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

// The entries of bodies [i0, i1) in body order (body_cell_key's keys, each body's in m order) into
// keys / body (room for 8 a body), without a branch on the cells: every body makes its 8 corners'
// keys and keeps those along its spilled axes (a corner c keeps iff c & ~spill == 0; increasing c is
// m's order). Along axis k a cell coordinate v adds A_k(v) = ((v & 1) << (half_bits + k)) +
// s_k · (v >> 1) to the key (s = 1, half[0], half[0]·half[1]): a cell's key is A_0(x) + A_1(y) +
// A_2(z) (cell_key: the type bits lie above the linear part, so the sum is its or). Returns the count.
template <class Key, class Real, class CellsOf>
std::size_t block_keys(const CellsOf& cells_of, const GridParams<Real>& g, std::size_t i0, std::size_t i1,
                       Key* keys, std::uint32_t* body) {
  const Key s[3] = {Key(1), Key(g.half[0]), Key(g.half[0]) * Key(g.half[1])};
  std::size_t n = 0;
  for (std::size_t i = i0; i < i1; ++i) {
    const BodyCells c = cells_of(i);
    Key a[3][2];
    for (int k = 0; k < 3; ++k)
      for (std::uint32_t o = 0; o < 2; ++o) {
        const std::uint32_t v = c.lo[k] + o;
        a[k][o] = (Key(v & 1u) << (g.half_bits + k)) + s[k] * Key(v >> 1);
      }
    const std::uint32_t skip = ~c.spill & 7u;
    for (std::uint32_t corner = 0; corner < 8; ++corner) {
      keys[n] = a[0][corner & 1u] + a[1][(corner >> 1) & 1u] + a[2][corner >> 2];
      body[n] = static_cast<std::uint32_t>(i);
      n += (corner & skip) == 0u;
    }
  }
  return n;
}

// CONTACTGRID_HOST_ENTRIES=grouped: the entries written grouped by their top digit (opt-in: it makes
// every entry's key twice, which on the 2-core EPYC and Xeon VMs measured costs more CPU than the
// body-order array's write and two reads save; BENCHMARKS.md §2); unset or `body-order`: body order,
// and the sort's every pass after. Read each call; the same sorted entries either way.
bool by_digit_wanted() {
  const char* k = std::getenv("CONTACTGRID_HOST_ENTRIES");
  return k != nullptr && std::string_view(k) == "grouped";
}

// The entries grouped by the top digit of their key (the key's bits from `shift` up): each thread
// counts the digits of its range of bodies' entries, the counts are scanned digit by digit and thread
// by thread within a digit, and each thread then writes its entries straight to their places. Within
// a group the entries keep body order (and a body's own in m order), as the sort's top-digit scatter
// of the body-order entries leaves them: the sort then only sorts each group by its low bits
// (radix_sort_buckets). Where one group would hold more than a sixteenth of the entries (or 4 times
// the mean, where the groups are few: keys that use few of their top bits), nothing is written and
// false is returned.
template <class Real, class Key, class CellsOf>
bool fill_by_digit(std::size_t n, const GridParams<Real>& g, int key_bits, int threads, Entries<Key>& out,
                   const CellsOf& cells_of) {
  int top = 1;  // about 2048 bodies a group or more (a group holds 1 to 8 entries a body), at most 256
  while (top < 8 && top < key_bits && (n >> (top + 1)) >= 2048) ++top;
  const int shift = key_bits - top;
  const std::size_t buckets = std::size_t(1) << top;
  const Key mask = Key(buckets - 1);
  const int nt = n > k_parallel_min ? threads : 1;
  std::vector<std::size_t> hist(std::size_t(nt) * buckets), start(buckets + 1);
  bool skewed = false;
#pragma omp parallel num_threads(nt)
  {
    const int t = omp_get_thread_num(), team = omp_get_num_threads();
    const std::size_t lo = n * t / team, hi = n * (t + 1) / team;
    std::size_t* h = hist.data() + std::size_t(t) * buckets;
    std::fill(h, h + buckets, std::size_t(0));
    // blocks of bodies: their entries made into a buffer (block_keys), then counted, and made again
    // and written
    std::vector<Key> block_key(8 * k_digit_block);
    std::vector<std::uint32_t> block_body(8 * k_digit_block);
    for (std::size_t b = lo; b < hi; b += k_digit_block) {
      const std::size_t m =
          block_keys(cells_of, g, b, std::min(hi, b + k_digit_block), block_key.data(), block_body.data());
      for (std::size_t k = 0; k < m; ++k) ++h[(block_key[k] >> shift) & mask];
    }
#pragma omp barrier
#pragma omp single
    {
      std::size_t sum = 0;
      for (std::size_t d = 0; d < buckets; ++d) {
        start[d] = sum;
        for (int u = 0; u < team; ++u) {
          const std::size_t c = hist[std::size_t(u) * buckets + d];
          hist[std::size_t(u) * buckets + d] = sum;
          sum += c;
        }
      }
      start[buckets] = sum;
      const std::size_t most = std::max(sum / 16, 4 * sum / buckets);  // 4x the mean where few groups
      for (std::size_t d = 0; d < buckets; ++d) skewed = skewed || start[d + 1] - start[d] > most;
      if (!skewed) {
        out.keys.resize(sum);
        out.body.resize(sum);
      }
    }
    if (!skewed) {
      Key* keys = out.keys.data();
      std::uint32_t* body = out.body.data();
      for (std::size_t b = lo; b < hi; b += k_digit_block) {
        const std::size_t m =
            block_keys(cells_of, g, b, std::min(hi, b + k_digit_block), block_key.data(), block_body.data());
        for (std::size_t k = 0; k < m; ++k) {
          const std::size_t at = h[(block_key[k] >> shift) & mask]++;
          keys[at] = block_key[k];
          body[at] = block_body[k];
        }
      }
    }
  }
  if (skewed) return false;
  out.digit_start = std::move(start);
  out.digit_shift = shift;
  return true;
}

}  // namespace

template <class Real, class Key>
std::uint64_t fill_entries(PackedBodies<Real>& p, const GridParams<Real>& g, int threads, Entries<Key>& out,
                           int key_bits) {
  const BodyCells* cells = p.cells.data();
  const auto cells_of = [&](std::size_t i) { return cells[i]; };
  out.digit_start.clear();
  std::uint64_t n_entries = 0;
  if (key_bits > 11 && p.ctrl.size() >= k_parallel_min && by_digit_wanted() &&
      fill_by_digit(p.ctrl.size(), g, key_bits, threads, out, cells_of))
    n_entries = out.size();
  else
    n_entries = fill_blocks(p, g, threads, out, cells_of);
  p.cells = {};
  p.count = {};
  return n_entries;
}

template std::uint64_t fill_entries(PackedBodies<float>&, const GridParams<float>&, int,
                                    Entries<std::uint32_t>&, int);
template std::uint64_t fill_entries(PackedBodies<float>&, const GridParams<float>&, int,
                                    Entries<std::uint64_t>&, int);
template std::uint64_t fill_entries(PackedBodies<double>&, const GridParams<double>&, int,
                                    Entries<std::uint32_t>&, int);
template std::uint64_t fill_entries(PackedBodies<double>&, const GridParams<double>&, int,
                                    Entries<std::uint64_t>&, int);

}  // namespace cg::detail::host
