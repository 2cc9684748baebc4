#pragma once
// The fixed order of the energy sums of the granular dynamics, shared by both backends: items in
// chunks of kEnergyChunk, each chunk summed from its first item to its last, then the chunks' sums
// in chunk order (the device: one thread per chunk, then the host). CPU = CUDA bit for bit.
#include <cstddef>

#include "core/config.hpp"

namespace cg::dem {

constexpr std::size_t kEnergyChunk = 4096;

inline std::size_t energy_chunks(std::size_t n) { return (n + kEnergyChunk - 1) / kEnergyChunk; }

// The sum of value(i) over chunk `c` of n items.
template <class F>
CG_HD double chunk_sum(std::size_t c, std::size_t n, F&& value) {
  double s = 0;
  const std::size_t end = (c + 1) * kEnergyChunk < n ? (c + 1) * kEnergyChunk : n;
  for (std::size_t i = c * kEnergyChunk; i < end; ++i) s = s + value(i);
  return s;
}

}  // namespace cg::dem
