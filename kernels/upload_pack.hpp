#pragma once
// The fp32 host path's upload rows (cuda/transfer.cuh): body i as the 16 bytes fp32's pack makes of
// it, Sphere<float>{float(p − origin), float(r)} (host/pack.cpp and cuda/pack.cuh's packed_sphere
// add the grid's radius margin on top), written on the host into the pinned slot that goes up. Half
// the bytes of the world doubles; the same bits as the device's own conversion.
#include <cstddef>

#include "core/vec3.hpp"

namespace cg::detail {

// Bodies [begin, end) of `position` / `radius` into dst[0 … end − begin), over `threads` OpenMP
// threads (0: all; one below 2^15 bodies).
void pack_upload_spheres(const Vec3<double>* position, const double* radius, const Vec3<double>& origin,
                         std::size_t begin, std::size_t end, Sphere<float>* dst, int threads);

}  // namespace cg::detail
