#pragma once
// The energies of the granular dynamics on the device, in the fixed order of core/dem_sum.hpp: one
// thread per chunk sums its items in order, the host adds the chunks' sums in order (as the CPU).
#include <vector>

#include "core/dem_sum.hpp"
#include "cuda/common.cuh"
#include "cuda/dem_state.cuh"

namespace cg::cuda {

// partials[c]: chunk c's kinetic, gravity (bodies) and elastic (contacts, walls) sums, as 4 doubles.
__global__ void dem_energy_kernel(dem::BodyArrays b, Vec3<double> gravity, const double* contact_energy,
                                  std::size_t contacts, const double* wall_energy, std::size_t chunks,
                                  double* partials) {
  const std::size_t c = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (c >= chunks) return;
  partials[4 * c + 0] =
      dem::chunk_sum(c, b.count, [&](std::size_t i) { return dem::body_energy(i, b, gravity).kinetic; });
  partials[4 * c + 1] =
      dem::chunk_sum(c, b.count, [&](std::size_t i) { return dem::body_energy(i, b, gravity).gravity; });
  partials[4 * c + 2] = dem::chunk_sum(c, contacts, [&](std::size_t k) { return contact_energy[k]; });
  partials[4 * c + 3] = dem::chunk_sum(c, b.count, [&](std::size_t i) { return wall_energy[i]; });
}

}  // namespace cg::cuda

namespace cg::detail {

inline DemEnergies dem_energy_stage(CudaDem& d, std::size_t contacts, Vec3<double> gravity) {
  const std::size_t chunks = std::max(dem::energy_chunks(d.count), dem::energy_chunks(contacts));
  DemEnergies e;
  if (chunks == 0) return e;
  d.partials.reserve(4 * chunks, true);
  cuda::dem_energy_kernel<<<cuda::blocks_for(chunks), cuda::kBlock>>>(
      d.arrays(), gravity, d.contact_energy.data(), contacts, d.wall_energy.data(), chunks,
      d.partials.data());
  CG_CUDA_CHECK_LAUNCH("dem_energy");
  std::vector<double> h(4 * chunks);
  CG_CUDA_CHECK(cudaMemcpy(h.data(), d.partials.data(), h.size() * sizeof(double), cudaMemcpyDeviceToHost));
  double kinetic = 0, grav = 0, contact = 0, wall = 0;  // each in chunk order, as the CPU's sums
  for (std::size_t c = 0; c < chunks; ++c) {
    kinetic = kinetic + h[4 * c + 0];
    grav = grav + h[4 * c + 1];
    contact = contact + h[4 * c + 2];
    wall = wall + h[4 * c + 3];
  }
  e.kinetic = kinetic;
  e.gravity = grav;
  e.elastic = contact + wall;
  return e;
}

}  // namespace cg::detail
