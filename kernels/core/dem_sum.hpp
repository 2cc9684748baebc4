#pragma once
// The fixed order of the energy sums of the granular dynamics, shared by both backends and by the
// ranks under mpirun: a tree of fan-in kEnergyChunk. The items in chunks of kEnergyChunk, each chunk
// summed from its first item to its last; then the chunks' sums, in chunks of kEnergyChunk the same
// way; and so on until one value is left (n ≤ kEnergyChunk: the plain sum in item order). Every chunk
// of a level is independent (the device: one thread per chunk and one launch per level; the host:
// OpenMP over the chunks), and the order is the same whatever the threads: CPU = CUDA bit for bit.
#include <cstddef>
#include <vector>

#include "core/config.hpp"

namespace cg::dem {

constexpr std::size_t kEnergyChunk = 32;

CG_HD std::size_t energy_chunks(std::size_t n) { return (n + kEnergyChunk - 1) / kEnergyChunk; }

// The sum of value(i) over chunk `c` of n items.
template <class F>
CG_HD double chunk_sum(std::size_t c, std::size_t n, F&& value) {
  double s = 0;
  const std::size_t end = (c + 1) * kEnergyChunk < n ? (c + 1) * kEnergyChunk : n;
  for (std::size_t i = c * kEnergyChunk; i < end; ++i) s = s + value(i);
  return s;
}

// The tree's sum of value(i) over n items (host). level(m, in, out): out[c] = chunk_sum(c, m, in)
// for every chunk c of m items (for_chunks(chunks, f) calls f(c) for each: serial or in parallel).
template <class F, class ForChunks>
double tree_sum(std::size_t n, F&& value, ForChunks&& for_chunks) {
  if (n == 0) return 0;
  std::vector<double> level(energy_chunks(n));
  for_chunks(level.size(), [&](std::size_t c) { level[c] = chunk_sum(c, n, value); });
  while (level.size() > 1) {
    std::vector<double> next(energy_chunks(level.size()));
    const double* in = level.data();
    const std::size_t m = level.size();
    for_chunks(next.size(),
               [&](std::size_t c) { next[c] = chunk_sum(c, m, [in](std::size_t i) { return in[i]; }); });
    level.swap(next);
  }
  return level[0];
}

// The same, one chunk after another.
template <class F>
double tree_sum(std::size_t n, F&& value) {
  return tree_sum(n, value, [](std::size_t chunks, auto&& f) {
    for (std::size_t c = 0; c < chunks; ++c) f(c);
  });
}

}  // namespace cg::dem
