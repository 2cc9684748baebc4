// Host stages entries and sort by the cell sort (see stages.hpp): the bodies sorted by the super-cell
// of their lowest cell, then the grid's entries counted and written cell by cell from that order, with
// the walk's bodies beside them. The entry sort (entries.cpp, sort.cpp, and the pair stage's gather)
// writes every entry in body order, sorts it by its key over the whole array and gathers each entry's
// body at random; here one key a body is sorted, the bodies are gathered once, and the entries are
// written once, into windows of the output that slide with the bodies' super-cells.
#include <omp.h>

#include <algorithm>
#include <cstdlib>
#include <ranges>
#include <string_view>
#include <vector>

#include "host/radix_sort.hpp"
#include "host/stages.hpp"

namespace cg::detail::host {

namespace {

// The gather of the walk's bodies: chunks of this many super-cells (a chunk's records and those of the
// layer before it, a few hundred kilobytes at a few bodies a super-cell, stay in the cache).
constexpr std::uint64_t k_gather_cells = 256;

// Thread t's counters: one row of `width` super-cells from `lo` for each of the 8 cell types, the
// super-cells its bodies' cells can fall in (its blocks, and `reach` past the last).
struct CountWindow {
  std::uint64_t lo = 0, width = 0;
  std::uint32_t* count = nullptr;  // 8 rows of width, in the call's one array of counters
  bool holds(std::uint64_t lin) const { return lin >= lo && lin - lo < width; }
};

// Calls f(type, lin) for each cell of a body whose lowest cell lies in super-cell `block`, control byte
// `ctrl` (parity of the lowest cell, spilled axes): the cell lo + c for each c within the spilled axes
// has type parity ^ c and super-cell block + the axes where lo is odd and c steps (spilled_cell_key).
template <class F>
inline void for_each_cell(std::uint64_t block, std::uint32_t ctrl, std::uint64_t h0, std::uint64_t h01,
                          F&& f) {
  const std::uint32_t parity = ctrl & 7u, spill = (ctrl >> 3) & 7u;
  for (std::uint32_t c = spill;; c = (c - 1) & spill) {
    const std::uint32_t up = c & parity;
    f(parity ^ c, block + (up & 1u) + ((up >> 1) & 1u) * h0 + ((up >> 2) & 1u) * h01);
    if (c == 0) break;
  }
}

// A body's cells from its control byte, for a thread's window of counters: for each ctrl (64) and
// each c of the 8 subsets of the axes, for_each_cell's cell as its counter's place in the window less
// the body's super-cell (type · width plus the super-cell step), and in `in` bit c where c lies
// within the spilled axes (a cell of the body). The count adds that bit at all eight places: no branch
// on the body's number of cells, whose mispredictions cost the loop more than its eight adds (all
// eight places lie in the window, which reaches a layer of super-cells past its last body's).
struct CellPlaces {
  std::uint64_t at[64][8];
  std::uint8_t in[8];  // by the spilled axes
  CellPlaces(std::uint64_t width, std::uint64_t h0, std::uint64_t h01) {
    for (std::uint32_t ctrl = 0; ctrl < 64; ++ctrl) {
      const std::uint32_t parity = ctrl & 7u;
      for (std::uint32_t c = 0; c < 8; ++c) {
        const std::uint32_t up = c & parity;
        at[ctrl][c] = (parity ^ c) * width + (up & 1u) + ((up >> 1) & 1u) * h0 + ((up >> 2) & 1u) * h01;
      }
    }
    for (std::uint32_t spill = 0; spill < 8; ++spill) {
      in[spill] = 0;
      for (std::uint32_t c = 0; c < 8; ++c)
        if ((c & ~spill) == 0) in[spill] = static_cast<std::uint8_t>(in[spill] | (1u << c));
    }
  }
};

}  // namespace

bool cell_bodies_by_chunks() {
  const char* k = std::getenv("CONTACTGRID_HOST_CELL_BODIES");
  return k == nullptr || std::string_view(k) != "types";
}

bool cell_sort_packs_blocks() {
  const char* k = std::getenv("CONTACTGRID_HOST_ENTRIES");
  return k == nullptr || std::string_view(k) != "cells-via-cells";
}

template <class Real>
bool cell_sort_wanted(const GridParams<Real>& g, std::size_t bodies, bool report_mask) {
  const char* k = std::getenv("CONTACTGRID_HOST_ENTRIES");
  if (k != nullptr && std::string_view(k) != "cells" && std::string_view(k) != "cells-via-cells")
    return false;
  if (report_mask || bodies >= (std::size_t(1) << 29)) return false;  // < 2^32 entries: 32-bit counts
  if (g.half_bits > k_block_bits) return false;                       // the super-cell in a block key
  const long double cells = 8.0L * g.half[0] * g.half[1] * g.half[2];
  return cells <= 4.0L * bodies + 65536.0L;
}

template <class Real>
void block_sort(PackedBodies<Real>& p, const GridParams<Real>& g, int threads, BlockOrder<Real>& out) {
  const std::size_t n = p.spheres.size();
  out.block.resize(n);
  out.ctrl.resize(n);
  out.bodies.resize(n);
  constexpr std::size_t ahead = 32;  // the bodies of a super-cell are random places in input order
  if (!p.block.empty()) {            // pack's keys, body index above block key: one array of 8 bytes a body
    Array<std::uint64_t> keys;
    keys.swap(p.block);
    p.cells = {};
    p.count = {};
    // stable: the bodies of a super-cell grouped by their spilled axes, each group's ascending
    radix_sort_keys(keys, g.half_bits + 3, threads);
    constexpr std::uint32_t low = (std::uint32_t(1) << k_block_bits) - 1u;
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
    for (std::size_t j = 0; j < n; ++j) {
      if (j + ahead < n) __builtin_prefetch(p.spheres.data() + (keys[j + ahead] >> 32));
      const std::uint32_t b = static_cast<std::uint32_t>(keys[j] >> 32),
                          key = static_cast<std::uint32_t>(keys[j]);
      const Sphere<Real> s = p.spheres[b];  // the control byte from the key: the spheres alone at random
      const std::uint32_t ctrl = (key >> (3 + k_block_bits)) | ((key & 7u) << 3);
      out.block[j] = (key >> 3) & low;
      out.ctrl[j] = static_cast<std::uint8_t>(ctrl);
      out.bodies[j] = {s.x, s.y, s.z, s.r + p.inflation, b, ctrl};  // a skin: the inflated spheres
    }
    return;
  }
  // the former path (CONTACTGRID_HOST_ENTRIES=cells-via-cells, and the centre cut's cells): the
  // super-cells from the cells, sorted with the body indices, the control bytes gathered
  const BodyCells* cells = p.cells.data();
  Array<std::uint32_t> body(n);
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    out.block[i] = super_cell(cells[i], g);
    body[i] = static_cast<std::uint32_t>(i);
  }
  p.cells = {};
  p.count = {};
  radix_sort(out.block, body, g.half_bits, threads);  // stable: a super-cell's bodies ascend
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t j = 0; j < n; ++j) {
    if (j + ahead < n) __builtin_prefetch(p.spheres.data() + body[j + ahead]);
    const std::uint32_t b = body[j];
    const Sphere<Real> s = p.spheres[b];
    out.ctrl[j] = p.ctrl[b];
    out.bodies[j] = {s.x, s.y, s.z, s.r + p.inflation, b, p.ctrl[b]};
  }
}

// Each thread takes a fixed share of the sorted bodies: it counts their entries per cell in its window,
// the counts are scanned type by type (in parallel over the types), super-cell by super-cell and thread
// by thread within one, and each thread then writes its entries to their places.
template <class Real, class Key>
std::uint64_t cell_sort(BlockOrder<Real>& o, const GridParams<Real>& g, int threads, Entries<Key>& out,
                        EntryBodies<Real>& eb) {
  const std::size_t n = o.block.size();
  const std::uint64_t h0 = g.half[0], h01 = h0 * g.half[1];
  const std::uint64_t reach = 1 + h0 + h01;  // the farthest super-cell of a body's cells past its own
  const int nt = n > k_parallel_min ? std::max(1, threads) : 1;
  std::vector<CountWindow> win(std::size_t(nt) + 1);
  Array<std::uint32_t> counters;  // every window's, one array: pooled storage, no fresh pages a call
  std::uint64_t type_start[9] = {};
  std::uint64_t lin_begin = 0, lin_end = 0;  // the windows' union
  out.digit_start.clear();
  const bool by_chunks = cell_bodies_by_chunks();  // the walk's bodies gathered chunk by chunk
  std::vector<std::size_t> chunk_start;            // type by type, each chunk's first entry
  std::size_t n_chunks = 0;
  const bool fixed = cell_sort_packs_blocks();  // the count without branches (else the former count)
#pragma omp parallel num_threads(nt)
  {
    const int team = omp_get_num_threads(), t = omp_get_thread_num();
    const std::size_t j0 = n * std::size_t(t) / std::size_t(team),
                      j1 = n * std::size_t(t + 1) / std::size_t(team);
    CountWindow& w = win[std::size_t(t)];
    if (j1 > j0) {
      w.lo = o.block[j0];
      w.width = std::uint64_t(o.block[j1 - 1]) + reach + 1 - w.lo;
    }
#pragma omp barrier
#pragma omp single
    {
      std::size_t total = 0;
      for (int u = 0; u < team; ++u) total += 8 * win[std::size_t(u)].width;
      counters.resize(total);
      std::size_t at = 0;
      for (int u = 0; u < team; ++u) {
        win[std::size_t(u)].count = counters.data() + at;
        at += 8 * win[std::size_t(u)].width;
      }
    }
    if (j1 > j0 && !fixed) {
      std::uint32_t* count = w.count;
      std::fill(count, count + 8 * w.width, 0u);
      for (std::size_t j = j0; j < j1; ++j)
        for_each_cell(o.block[j], o.ctrl[j], h0, h01,
                      [&](std::uint32_t type, std::uint64_t lin) { ++count[type * w.width + (lin - w.lo)]; });
    } else if (j1 > j0) {  // eight adds a body, 0 or 1 each (CellPlaces)
      std::uint32_t* count = w.count;
      std::fill(count, count + 8 * w.width, 0u);
      const CellPlaces places(w.width, h0, h01);
      for (std::size_t j = j0; j < j1; ++j) {
        std::uint32_t* at = count + (o.block[j] - w.lo);
        const std::uint32_t ctrl = o.ctrl[j], in = places.in[ctrl >> 3];
        const std::uint64_t* step = places.at[ctrl];
        for (std::uint32_t c = 0; c < 8; ++c) at[step[c]] += (in >> c) & 1u;
      }
    }
#pragma omp barrier
#pragma omp single
    {
      lin_begin = ~std::uint64_t(0);
      for (int u = 0; u < team; ++u)
        if (win[std::size_t(u)].width > 0) {
          lin_begin = std::min(lin_begin, win[std::size_t(u)].lo);
          lin_end = std::max(lin_end, win[std::size_t(u)].lo + win[std::size_t(u)].width);
        }
      if (lin_end == 0) lin_begin = 0;
    }
    // each type's total, then every cell's first place for each thread (windows ascend in lo and end)
#pragma omp for schedule(static)
    for (int type = 0; type < 8; ++type) {
      std::uint64_t total = 0;
      for (int u = 0; u < team; ++u) {
        const CountWindow& v = win[std::size_t(u)];
        for (std::uint64_t x = 0; x < v.width; ++x) total += v.count[std::size_t(type) * v.width + x];
      }
      type_start[type + 1] = total;
    }
#pragma omp single
    {
      for (int type = 0; type < 8; ++type) type_start[type + 1] += type_start[type];
      const std::size_t n_entries = type_start[8];
      out.keys.resize(n_entries);
      out.body.resize(n_entries);
      resize_entry_bodies(eb, n_entries);
      n_chunks = (lin_end - lin_begin + k_gather_cells - 1) / k_gather_cells;
      chunk_start.resize(8 * (n_chunks + 1));
      for (int type = 0; type < 8; ++type)
        chunk_start[std::size_t(type) * (n_chunks + 1) + n_chunks] = type_start[type + 1];
    }
#pragma omp for schedule(static)
    for (int type = 0; type < 8; ++type) {
      std::uint64_t at = type_start[type];
      std::size_t* starts = chunk_start.data() + std::size_t(type) * (n_chunks + 1);
      int first = 0, last = -1;  // the windows holding lin: [first, last], some of them empty
      for (std::uint64_t lin = lin_begin; lin < lin_end; ++lin) {
        if ((lin - lin_begin) % k_gather_cells == 0) starts[(lin - lin_begin) / k_gather_cells] = at;
        while (first < team && win[std::size_t(first)].lo + win[std::size_t(first)].width <= lin) ++first;
        while (last + 1 < team &&
               (win[std::size_t(last + 1)].width == 0 || win[std::size_t(last + 1)].lo <= lin))
          ++last;
        for (int u = first; u <= last; ++u) {
          CountWindow& v = win[std::size_t(u)];
          if (!v.holds(lin)) continue;
          std::uint32_t& c = v.count[std::size_t(type) * v.width + (lin - v.lo)];
          const std::uint32_t m = c;
          c = static_cast<std::uint32_t>(at);
          at += m;
        }
      }
    }
    // each entry's key and the sorted place of its body (in out.body until the gather below): two
    // arrays written in the windows, each cell's places filled in two visits a layer of super-cells apart
    if (j1 > j0) {
      std::uint32_t* count = w.count;
      Key* keys = out.keys.data();
      std::uint32_t* place = out.body.data();
      const std::uint64_t lo = w.lo, width = w.width;
      const int half_bits = g.half_bits;
      for (std::size_t j = j0; j < j1; ++j)
        for_each_cell(o.block[j], o.ctrl[j], h0, h01, [&](std::uint32_t type, std::uint64_t lin) {
          const std::uint32_t at = count[type * width + (lin - lo)]++;
          keys[at] = (Key(type) << half_bits) | Key(lin);
          place[at] = static_cast<std::uint32_t>(j);
        });
    }
#pragma omp barrier
    std::uint32_t* body = out.body.data();
    const auto gather = [&](std::size_t e0, std::size_t e1) {
      for (std::size_t e = e0; e < e1; ++e) {
        const std::uint32_t j = body[e];
        const OrderedBody<Real>& a = o.bodies[j];
        body[e] = a.body;
        eb.x[e] = a.x;
        eb.y[e] = a.y;
        eb.z[e] = a.z;
        eb.r[e] = a.r;
        eb.ctrl[e] = a.ctrl;
      }
    };
    const std::size_t n_entries = type_start[8];
    if (by_chunks) {
      // the walk's bodies chunk by chunk of k_gather_cells super-cells, the eight types of a chunk
      // together: a chunk's entries read the records of its own super-cells and of the layer before
      // (in the cache from the chunks before), so the records come from memory about once. A thread
      // takes a run of chunks holding about an even share of the entries (the chunks before a
      // thread's first hold fewer than t / team of them), so that the layer behind its chunks is
      // the one it read itself.
      const auto before = [&](std::size_t k) {  // the entries in chunks [0, k)
        std::size_t sum = 0;
        for (int type = 0; type < 8; ++type)
          sum += chunk_start[std::size_t(type) * (n_chunks + 1) + k] - type_start[type];
        return sum;
      };
      const auto first_chunk = [&](int u) {  // the first chunk k with before(k) >= n_entries · u / team
        const std::size_t want = n_entries * std::size_t(u) / std::size_t(team);
        const auto chunks = std::views::iota(std::size_t(0), n_chunks);
        return std::size_t(
            std::ranges::partition_point(chunks, [&](std::size_t k) { return before(k) < want; }) -
            chunks.begin());
      };
      const std::size_t k1 = t + 1 == team ? n_chunks : first_chunk(t + 1);
      for (std::size_t k = t == 0 ? 0 : first_chunk(t); k < k1; ++k)
        for (int type = 0; type < 8; ++type) {
          const std::size_t* starts = chunk_start.data() + std::size_t(type) * (n_chunks + 1);
          gather(starts[k], starts[k + 1]);
        }
    } else {
      // CONTACTGRID_HOST_CELL_BODIES=types: each entry's from its body's sorted place, an even share
      // of the entries a thread, type after type (each type's entries read all their bodies' records)
      gather(n_entries * std::size_t(t) / std::size_t(team),
             n_entries * std::size_t(t + 1) / std::size_t(team));
    }
  }
  o = {};
  return type_start[8];
}

template bool cell_sort_wanted(const GridParams<float>&, std::size_t, bool);
template bool cell_sort_wanted(const GridParams<double>&, std::size_t, bool);
template void block_sort(PackedBodies<float>&, const GridParams<float>&, int, BlockOrder<float>&);
template void block_sort(PackedBodies<double>&, const GridParams<double>&, int, BlockOrder<double>&);
template std::uint64_t cell_sort(BlockOrder<float>&, const GridParams<float>&, int, Entries<std::uint32_t>&,
                                 EntryBodies<float>&);
template std::uint64_t cell_sort(BlockOrder<float>&, const GridParams<float>&, int, Entries<std::uint64_t>&,
                                 EntryBodies<float>&);
template std::uint64_t cell_sort(BlockOrder<double>&, const GridParams<double>&, int, Entries<std::uint32_t>&,
                                 EntryBodies<double>&);
template std::uint64_t cell_sort(BlockOrder<double>&, const GridParams<double>&, int, Entries<std::uint64_t>&,
                                 EntryBodies<double>&);

}  // namespace cg::detail::host
