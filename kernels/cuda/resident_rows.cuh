#pragma once
// A halo's rows on the DEVICE (Engine::gather_rows, scatter_rows, copy_rows, rows_outside; the host's
// are resident_rows.hpp): one thread a listed row, reading or writing the resident arrays at the
// list's rows and a packed row at its place (4 doubles: position, radius; 8 with the orientation).
// The lists are u32 (a rank holds fewer than 2^32 rows: the engine checks it).
#include <cstddef>
#include <cstdint>

#include "cuda/common.cuh"

namespace cg::cuda {

// Row k of `out` := resident row list[k] (`orient` null: positions and radii only).
__global__ void __launch_bounds__(kBlock)
    pack_rows_kernel(const double* __restrict__ pos, const double* __restrict__ rad,
                     const double* __restrict__ orient, const std::uint32_t* __restrict__ list, std::size_t m,
                     double* __restrict__ out) {
  const std::size_t k = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (k >= m) return;
  const std::size_t i = list[k];
  double* row = out + k * (orient ? 8 : 4);
  row[0] = pos[3 * i];
  row[1] = pos[3 * i + 1];
  row[2] = pos[3 * i + 2];
  row[3] = rad[i];
  if (orient)
    for (int w = 0; w < 4; ++w) row[4 + w] = orient[4 * i + w];
}

// Resident row list[k] := row k of `in`.
__global__ void __launch_bounds__(kBlock)
    unpack_rows_kernel(const double* __restrict__ in, const std::uint32_t* __restrict__ list, std::size_t m,
                       double* __restrict__ pos, double* __restrict__ rad, double* __restrict__ orient) {
  const std::size_t k = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (k >= m) return;
  const std::size_t i = list[k];
  const double* row = in + k * (orient ? 8 : 4);
  pos[3 * i] = row[0];
  pos[3 * i + 1] = row[1];
  pos[3 * i + 2] = row[2];
  rad[i] = row[3];
  if (orient)
    for (int w = 0; w < 4; ++w) orient[4 * i + w] = row[4 + w];
}

// Row to_list[k] of one engine's resident arrays := row from_list[k] of another's.
__global__ void __launch_bounds__(kBlock)
    copy_rows_kernel(const double* __restrict__ from_pos, const double* __restrict__ from_rad,
                     const double* __restrict__ from_orient, const std::uint32_t* __restrict__ from_list,
                     const std::uint32_t* __restrict__ to_list, std::size_t m, double* __restrict__ pos,
                     double* __restrict__ rad, double* __restrict__ orient) {
  const std::size_t k = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (k >= m) return;
  const std::size_t i = from_list[k], j = to_list[k];
  pos[3 * j] = from_pos[3 * i];
  pos[3 * j + 1] = from_pos[3 * i + 1];
  pos[3 * j + 2] = from_pos[3 * i + 2];
  rad[j] = from_rad[i];
  if (orient)
    for (int w = 0; w < 4; ++w) orient[4 * j + w] = from_orient[4 * i + w];
}

// The select's test of rows_outside: the centre's coordinate along `axis` not in (lo, hi).
struct OutsideInterval {
  const double* pos;
  int axis;
  double lo, hi;
  __device__ bool operator()(std::uint32_t i) const {
    const double x = pos[3 * std::size_t(i) + axis];
    return !(x > lo && x < hi);
  }
};

}  // namespace cg::cuda
