// Scenes the tests build by hand from the generators' counter-based randomness (counter_rng.hpp):
// Gaussian clusters, a lattice and a sphere/ellipsoid mix (generate.hpp).
#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <string>
#include <vector>

#include "errors.hpp"
#include "scene/counter_rng.hpp"
#include "scene/generate.hpp"

namespace cg {

using namespace scene_rng;

namespace {
constexpr const char* kSoftwareVersion = CONTACTGRID_VERSION;
}  // namespace

Scene make_clustered_scene(std::uint64_t n, std::uint64_t seed, int clusters) {
  if (clusters < 1)
    throw UsageError(fmt::format("clustered scene: clusters must be >= 1 (got {})", clusters));
  const CounterRng rng(seed);
  const std::uint64_t k =
      std::min<std::uint64_t>(static_cast<std::uint64_t>(clusters), std::max<std::uint64_t>(n, 1));
  const double per_cluster = std::ceil(static_cast<double>(n) / static_cast<double>(k));
  const double sigma = std::max(1.0, std::cbrt(per_cluster / 12));
  const double spread = 8 * sigma * std::cbrt(static_cast<double>(k));
  std::vector<Vec3<double>> centres(k);
  for (std::uint64_t c = 0; c < k; ++c) {  // cluster centres: indices past the bodies' own
    std::uint64_t index = (std::uint64_t(1) << 59) + c;
    centres[c] = {spread * rng.unit(index, kX), spread * rng.unit(index, kY), spread * rng.unit(index, kZ)};
  }
  Scene scene;
  scene.sphere_position.resize(n);
  scene.sphere_radius.resize(n);
  for (std::uint64_t i = 0; i < n; ++i) {
    const Vec3<double>& c = centres[i % k];
    scene.sphere_position[i] = {c.x + sigma * rng.normal(i, kGauss0, kGauss1),
                                c.y + sigma * rng.normal(i, kGauss2, kGauss3),
                                c.z + sigma * rng.normal(i, kX, kY)};
    scene.sphere_radius[i] = std::min(1.0, 0.5 + 0.5 * rng.unit(i, kRadius));
  }
  scene.radius_low = 0.5;
  scene.radius_high = 1.0;
  scene.attributes["generator"] = std::string("clustered");
  scene.attributes["count"] = static_cast<std::int64_t>(n);
  scene.attributes["seed"] = std::bit_cast<std::int64_t>(seed);
  scene.attributes["clusters"] = static_cast<std::int64_t>(k);
  scene.attributes["sigma"] = sigma;
  scene.attributes["software_version"] = std::string(kSoftwareVersion);
  return scene;
}

Scene make_lattice_scene(std::uint32_t nx, std::uint32_t ny, std::uint32_t nz, double spacing, double radius,
                         Vec3<double> origin) {
  if (!(std::isfinite(spacing) && std::isfinite(radius) && radius > 0))
    throw UsageError(
        fmt::format("lattice scene: need finite spacing and radius > 0 (got {}, {})", spacing, radius));
  Scene scene;
  const std::size_t n = std::size_t(nx) * ny * nz;
  scene.sphere_position.reserve(n);
  scene.sphere_radius.assign(n, radius);
  for (std::uint32_t k = 0; k < nz; ++k)
    for (std::uint32_t j = 0; j < ny; ++j)
      for (std::uint32_t i = 0; i < nx; ++i)
        scene.sphere_position.push_back(
            {origin.x + spacing * i, origin.y + spacing * j, origin.z + spacing * k});
  scene.radius_low = radius;
  scene.radius_high = radius;
  scene.attributes["generator"] = std::string("lattice");
  scene.attributes["spacing"] = spacing;
  scene.attributes["software_version"] = std::string(kSoftwareVersion);
  return scene;
}

Scene make_ellipsoid_scene(std::uint64_t spheres, std::uint64_t ellipsoids, std::uint64_t seed) {
  const CounterRng rng(seed);
  const std::uint64_t n = spheres + ellipsoids;
  const double edge = n == 0 ? 1.0 : box_edge(n, RadiusLaw::uniform, 0.5, 1.0, 0.4);
  auto coordinate = [&](std::uint64_t i, unsigned stream) {
    return std::min(edge * rng.unit(i, stream), std::nextafter(edge, 0.0));
  };
  Scene scene;
  for (std::uint64_t i = 0; i < spheres; ++i) {
    scene.sphere_position.push_back({coordinate(i, kX), coordinate(i, kY), coordinate(i, kZ)});
    scene.sphere_radius.push_back(std::min(1.0, 0.5 + 0.5 * rng.unit(i, kRadius)));
  }
  for (std::uint64_t i = spheres; i < n; ++i) {  // body id i
    scene.ellipsoid_position.push_back({coordinate(i, kX), coordinate(i, kY), coordinate(i, kZ)});
    auto axis = [&](unsigned stream) { return std::min(1.0, 0.25 + 0.75 * rng.unit(i, stream)); };
    scene.ellipsoid_semi_axes.push_back({axis(kAxisA), axis(kAxisB), axis(kAxisC)});
    scene.ellipsoid_orientation.push_back(random_quaternion(rng, i));
  }
  scene.radius_low = 0.25;
  scene.radius_high = 1.0;
  scene.attributes["generator"] = std::string("ellipsoids");
  scene.attributes["seed"] = std::bit_cast<std::int64_t>(seed);
  scene.attributes["box_edge"] = edge;
  scene.attributes["software_version"] = std::string(kSoftwareVersion);
  return scene;
}

}  // namespace cg
