#pragma once
// How far a set of contacts is from the exact reference, judged with a rounding band (docs/FORMAT.md §3):
// a pair whose exact |distance| <= band may be reported or not; outside the band every decision must
// equal the reference's. The numbers `contactgrid study` reports and its tests check.
//
//   missed      reference contacts with distance < −band that the set lacks
//   extra       reported pairs whose exact distance is > band (not in the reference, or held by a
//               reference computed with a wider slack)
//   borderline  reference pairs with |distance| <= band (either decision right), reported or not
//   matched     reported pairs the reference holds (values compared on these)
//   position    max over matched pairs and both bodies of |p − p_ref| / r (r: that body's bounding
//               radius), its 99th percentile (nearest rank) over pairs
//   normal      max angle between n and n_ref, degrees (atan2 of |n × n_ref| and n·n_ref: exact near 0)
//   distance    max |distance − distance_ref| (length units)
// A NaN value counts as an infinite error.
#include <cstdint>
#include <span>
#include <vector>

#include "core/vec3.hpp"
#include "reference/sphere_reference.hpp"

namespace cg::exact {

// One reported contact, in double whatever the precision it was computed in.
struct FoundContact {
  std::int64_t a, b;
  double distance;
  Vec3<double> n, pa, pb;
};

struct ContactErrors {
  std::uint64_t reported = 0, reference = 0, matched = 0;
  std::uint64_t missed = 0, extra = 0, borderline = 0;
  double max_position_rel = 0, p99_position_rel = 0, max_normal_deg = 0, max_distance = 0;
};

// `found` and `reference` sorted by (a, b) (as the engine and reference_contacts return them),
// `reference` holding every pair with exact distance <= band (reference_contacts with slack >= band);
// `radius[i]`: body i's bounding radius.
ContactErrors compare_with_reference(std::span<const FoundContact> found,
                                     std::span<const RefContact> reference, std::span<const double> radius,
                                     double band);

// The angle between two directions in degrees (0 … 180), accurate near 0 and 180.
double angle_deg(Vec3<double> u, Vec3<double> v);

}  // namespace cg::exact
