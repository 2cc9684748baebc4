#pragma once
// A skin's bounds: the bounds of bodies whose radii grow by `d` (EngineOptions::skin's inflated spheres):
// what the engine plans a skin's grid from, and what the simulation's slots path plans the same cell edge
// from (kernels/dem_slots.cpp). Host only.
#include <algorithm>
#include <cmath>

#include "grid_plan.hpp"

namespace cg {

// Boxes, largest radius and the radius moments of the cell-size model, of the radii r + d.
inline Bounds inflated_bounds(Bounds b, double d) {
  b.lo = {b.lo.x - d, b.lo.y - d, b.lo.z - d};
  b.hi = {b.hi.x + d, b.hi.y + d, b.hi.z + d};
  b.r_max += d;
  const double n = double(b.count), s1 = b.r_sum[0], s2 = b.r_sum[1], s3 = b.r_sum[2];
  b.r_sum[0] = s1 + n * d;
  b.r_sum[1] = s2 + 2 * d * s1 + n * d * d;
  b.r_sum[2] = s3 + 3 * d * s2 + 3 * d * d * s1 + n * d * d * d;
  return b;
}

// The largest magnitude of a local coordinate of the bodies' boxes in a frame with this origin (a
// skin's coordinate bound, core/skin.hpp).
inline double coordinate_magnitude(const Bounds& b, const Vec3<double>& origin) {
  return std::max({std::abs(b.lo.x - origin.x), std::abs(b.lo.y - origin.y), std::abs(b.lo.z - origin.z),
                   std::abs(b.hi.x - origin.x), std::abs(b.hi.y - origin.y), std::abs(b.hi.z - origin.z)});
}

}  // namespace cg
