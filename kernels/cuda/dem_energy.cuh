#pragma once
// The energies of the granular dynamics on the device, in the fixed order of core/dem_sum.hpp (the
// CPU's): the first level sums each chunk of items (kinetic and gravity of the bodies, the contacts'
// and the walls' elastic energy: four series), one thread per chunk; each further level sums chunks
// of the last level's sums, one launch per level, until each series is one value; the four values
// then cross to the host. Every level reads its input in whole chunks: O(items) bytes, all threads busy.
#include <algorithm>

#include "core/dem_sum.hpp"
#include "cuda/common.cuh"
#include "cuda/dem_state.cuh"

namespace cg::cuda {

// A level's four series: in[s] of count[s] items into out[s] (energy_chunks(count[s]) sums).
struct EnergySeries {
  const double* in[4];
  double* out[4];
  std::size_t count[4];
};

// The first level: chunk c of the bodies (kinetic, gravity, wall) and of the contacts.
__global__ void dem_energy_kernel(dem::BodyArrays b, Vec3<double> gravity, const double* contact_energy,
                                  std::size_t contacts, const double* wall_energy, std::size_t chunks,
                                  EnergySeries s) {
  const std::size_t c = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (c >= chunks) return;
  if (c < dem::energy_chunks(b.count)) {
    s.out[0][c] =
        dem::chunk_sum(c, b.count, [&](std::size_t i) { return dem::body_energy(i, b, gravity).kinetic; });
    s.out[1][c] =
        dem::chunk_sum(c, b.count, [&](std::size_t i) { return dem::body_energy(i, b, gravity).gravity; });
    s.out[3][c] = dem::chunk_sum(c, b.count, [&](std::size_t i) { return wall_energy[i]; });
  }
  if (c < dem::energy_chunks(contacts))
    s.out[2][c] = dem::chunk_sum(c, contacts, [&](std::size_t k) { return contact_energy[k]; });
}

// A further level: chunk c of each series that has one.
__global__ void dem_energy_level_kernel(EnergySeries s, std::size_t chunks) {
  const std::size_t c = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (c >= chunks) return;
  for (int k = 0; k < 4; ++k) {
    const double* in = s.in[k];
    if (c < dem::energy_chunks(s.count[k]))
      s.out[k][c] = dem::chunk_sum(c, s.count[k], [in](std::size_t i) { return in[i]; });
  }
}

}  // namespace cg::cuda

namespace cg::detail {

inline DemEnergies dem_energy_stage(CudaDem& d, std::size_t contacts, Vec3<double> gravity) {
  std::size_t count[4] = {d.count, d.count, contacts, d.count};
  std::size_t chunks[4], total = 0;
  for (int k = 0; k < 4; ++k) {
    chunks[k] = dem::energy_chunks(count[k]);
    total += chunks[k];
  }
  DemEnergies e;
  if (total == 0) return e;
  // two halves: a level's sums into one, the next level's into the other
  d.partials.reserve(2 * total, true);
  double* half[2] = {d.partials.data(), d.partials.data() + total};
  cuda::EnergySeries s{};
  auto place = [&](double* base) {
    std::size_t at = 0;
    for (int k = 0; k < 4; ++k) {
      s.out[k] = base + at;
      at += chunks[k];
    }
  };
  place(half[0]);
  const std::size_t first = *std::max_element(chunks, chunks + 4);
  cuda::dem_energy_kernel<<<cuda::blocks_for(first), cuda::kBlock>>>(
      d.arrays(), gravity, d.contact_energy.data(), contacts, d.wall_energy.data(), first, s);
  CG_CUDA_CHECK_LAUNCH("dem_energy");
  int h = 0;
  // (a series already down to one sum passes through a level as 0 + its sum: the same bits, a chunk's
  // sum being never −0)
  while (*std::max_element(chunks, chunks + 4) > 1) {
    for (int k = 0; k < 4; ++k) {
      s.in[k] = s.out[k];
      s.count[k] = chunks[k];
      chunks[k] = dem::energy_chunks(chunks[k]);
    }
    h = 1 - h;
    place(half[h]);
    const std::size_t next = *std::max_element(chunks, chunks + 4);
    cuda::dem_energy_level_kernel<<<cuda::blocks_for(next), cuda::kBlock>>>(s, next);
    CG_CUDA_CHECK_LAUNCH("dem_energy_level");
  }
  // each series' value: its one sum, side by side in the last level's half (a series of no items has
  // none, and its sum is 0)
  double last[4] = {0, 0, 0, 0}, v[4] = {0, 0, 0, 0};
  const std::size_t at = std::size_t(s.out[3] - s.out[0]) + chunks[3];
  CG_CUDA_CHECK(cudaMemcpy(last, s.out[0], at * sizeof(double), cudaMemcpyDeviceToHost));
  for (int k = 0; k < 4; ++k)
    if (chunks[k] > 0) v[k] = last[s.out[k] - s.out[0]];
  e.kinetic = v[0];
  e.gravity = v[1];
  e.elastic = v[2] + v[3];
  return e;
}

}  // namespace cg::detail
