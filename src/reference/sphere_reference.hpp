#pragma once
// The exact reference for spheres (and the reference contact every comparison uses): every pair with
// d <= ra + rb + slack, decided in long double from the double input (exact.hpp says how exact), by a
// sweep along x. Contact data by docs/FORMAT.md §3 in long double.
#include <cstdint>
#include <span>
#include <vector>

#include "core/vec3.hpp"
#include "reference/exact.hpp"

namespace cg::exact {

// One reference contact: ids a < b, the exact signed distance, the unit normal from b to a
// ((1, 0, 0) for coincident centres), the deepest points of a and b.
struct RefContact {
  std::int64_t a, b;
  LD distance;
  LD n[3];
  LD pa[3], pb[3];
};

// Every pair of spheres with d <= ra + rb + slack (slack >= 0 takes in the pairs a rounding band
// wide), sorted by (a, b); ids are indices into p and r. O(n log n + pairs) for scenes without huge
// overlaps along x.
std::vector<RefContact> reference_contacts(std::span<const Vec3<double>> p, std::span<const double> r,
                                           LD slack = 0);

// The contact of spheres a and b (ids a < b): docs/FORMAT.md §3 in long double.
RefContact sphere_contact(std::int64_t a, std::int64_t b, const Vec3<double>& pa, double ra,
                          const Vec3<double>& pb, double rb);

}  // namespace cg::exact
