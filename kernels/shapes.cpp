// Host check of the bodies' shape rows (bodies.hpp: validate_shapes): the predicate of
// core/shape.hpp, the messages the device-array path repeats (it re-runs this on the bad body's rows).
#include <omp.h>

#include <sstream>
#include <string>

#include "bodies.hpp"
#include "errors.hpp"

namespace cg {

std::size_t validate_shapes(const BodiesView& bodies) {
  const std::size_t n = bodies.size();
  if (bodies.shape.empty()) return 0;
  if (bodies.shape.size() != n || bodies.semi_axes.size() != n || bodies.orientation.size() != n)
    throw InputError("bodies: " + std::to_string(bodies.shape.size()) + " shape kinds, " +
                     std::to_string(bodies.semi_axes.size()) + " semi-axes and " +
                     std::to_string(bodies.orientation.size()) + " orientations for " + std::to_string(n) +
                     " bodies");
  // Parallel: the ellipsoid count and the first body whose rows fail, as a sequential scan would find
  // it (the smallest index); its message is written from that body's rows alone.
  auto fault_of = [&](std::size_t i, double& norm) {
    const std::uint8_t kind = static_cast<std::uint8_t>(bodies.shape[i]);
    const Vec3<double> e = bodies.semi_axes[i];
    const Quat<double> q = bodies.orientation[i];
    const double semi[3] = {e.x, e.y, e.z}, quat[4] = {q.w, q.x, q.y, q.z};
    return shape_fault(kind, bodies.radius[i], semi, quat, norm);
  };
  std::size_t ellipsoids = 0, first_bad = n;
  const int threads = n < (std::size_t(1) << 15) ? 1 : omp_get_max_threads();
#pragma omp parallel for num_threads(threads) schedule(static) reduction(+ : ellipsoids) \
    reduction(min : first_bad) if (threads > 1)
  for (std::size_t i = 0; i < n; ++i) {
    double norm = 0;
    ellipsoids += bodies.shape[i] == Shape::ellipsoid;
    if (fault_of(i, norm) != ShapeFault::none && i < first_bad) first_bad = i;
  }
  if (first_bad < n) {
    const std::size_t i = first_bad;
    const std::uint8_t kind = static_cast<std::uint8_t>(bodies.shape[i]);
    const Vec3<double> e = bodies.semi_axes[i];
    const Quat<double> q = bodies.orientation[i];
    double norm = 0;
    const ShapeFault f = fault_of(i, norm);
    std::ostringstream m;
    m << "body " << (bodies.id.empty() ? std::int64_t(i) : bodies.id[i]) << ": ";
    switch (f) {
      case ShapeFault::kind:
        m << "unknown shape kind " << int(kind) << " (0 sphere, 1 ellipsoid)";
        break;
      case ShapeFault::semi_axes:
        m << "ellipsoid semi-axes (" << e.x << ", " << e.y << ", " << e.z << ") must be finite and > 0";
        break;
      case ShapeFault::orientation:
        m << "ellipsoid orientation (" << q.w << ", " << q.x << ", " << q.y << ", " << q.z
          << ") is not a unit quaternion (norm " << norm << ", tolerance " << kQuaternionTolerance << ")";
        break;
      case ShapeFault::bounding_radius:
        m.precision(17);
        m << "bounding radius " << bodies.radius[i] << " is not the ellipsoid's largest semi-axis (" << e.x
          << ", " << e.y << ", " << e.z << ")";
        break;
      case ShapeFault::none:
        break;
    }
    throw InputError(m.str());
  }
  return ellipsoids;
}

}  // namespace cg
