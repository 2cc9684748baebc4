#pragma once
// Host-side data model of docs/FORMAT.md §1 (scenes) and the run record written with contacts (§2).
#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "core/vec3.hpp"
#include "host_vector.hpp"

namespace cg {

using AttrValue = std::variant<std::int64_t, double, std::string>;
using Attributes = std::map<std::string, AttrValue>;

// A scene in memory. Body ids: spheres 0 … N-1, ellipsoids N … N+M-1, in file order.
struct Scene {
  std::string source;                        // file it came from ("" if generated in memory)
  HostVector<Vec3<double>> sphere_position;  // (no zero sweep before the reader overwrites them)
  HostVector<double> sphere_radius;
  HostVector<Vec3<double>> ellipsoid_position;
  HostVector<Vec3<double>> ellipsoid_semi_axes;
  HostVector<std::array<double, 4>> ellipsoid_orientation;  // (w, x, y, z)
  // Motion (docs/FORMAT.md §5), world frame: one row per body of the group, or empty (absent: zero).
  std::vector<Vec3<double>> sphere_velocity, sphere_angular_velocity;
  std::vector<Vec3<double>> ellipsoid_velocity, ellipsoid_angular_velocity;
  std::optional<double> radius_low, radius_high;  // as promised by the file's root attributes
  Attributes attributes;                          // other root attributes (generator parameters)

  std::size_t sphere_count() const { return sphere_radius.size(); }
  std::size_t ellipsoid_count() const { return ellipsoid_semi_axes.size(); }
  std::size_t size() const { return sphere_count() + ellipsoid_count(); }
};

}  // namespace cg
