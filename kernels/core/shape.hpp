#pragma once
// Body shapes (docs/FORMAT.md §1), shared by host and device: the shape kind of a body, the input check of
// its shape data (the same predicate on the host path, compute/validate_shapes, and on the device-array
// path, a kernel), and the packed form the narrow phase reads (local Real semi-axes and the rotation
// built once per body).
#include <cstdint>

#include "core/config.hpp"
#include "core/quat.hpp"
#include "core/vec3.hpp"

namespace cg {

// One byte per body. A body's `radius` is always its bounding radius (the broad phase's sphere): the
// radius of a sphere, the largest semi-axis of an ellipsoid.
enum class Shape : std::uint8_t { sphere = 0, ellipsoid = 1 };

// An ellipsoid's orientation must be a unit quaternion to within this (| |q| - 1 | <= tolerance):
// data rounded to float32 (~1e-7) pass, a wrong column order or unnormalised data do not. The rotation
// is built from q / |q| either way (rotation_matrix), so the tolerance only rejects garbage.
inline constexpr double kQuaternionTolerance = 1e-5;

// What is wrong with a body's shape data (ShapeFault::none: valid). Checked after the centre and the
// radius (compute_bounds), in this order.
enum class ShapeFault : int { none = 0, kind, semi_axes, orientation, bounding_radius };

CG_HD bool finite_value(double v) { return v - v == 0.0; }  // false for ±inf and NaN

// The check of one body: kind a known Shape; for an ellipsoid, semi-axes finite and > 0, orientation
// finite with norm within kQuaternionTolerance of 1, and radius == the largest semi-axis (exactly:
// compute the radius as the max of the three). Spheres: nothing more than compute_bounds checks.
// norm_out: |q| (for the message).
CG_HD ShapeFault shape_fault(std::uint8_t kind, double radius, const double* semi, const double* q,
                             double& norm_out) {
  norm_out = 0;
  if (kind == static_cast<std::uint8_t>(Shape::sphere)) return ShapeFault::none;
  if (kind != static_cast<std::uint8_t>(Shape::ellipsoid)) return ShapeFault::kind;
  for (int k = 0; k < 3; ++k)
    if (!finite_value(semi[k]) || !(semi[k] > 0.0)) return ShapeFault::semi_axes;
  const double n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
#if defined(__CUDA_ARCH__)
  const double n = ::sqrt(n2);
#else
  const double n = __builtin_sqrt(n2);
#endif
  norm_out = n;
  const double dev = n - 1.0;
  if (!finite_value(n2) || !((dev < 0 ? -dev : dev) <= kQuaternionTolerance)) return ShapeFault::orientation;
  double m = semi[0];
  if (semi[1] > m) m = semi[1];
  if (semi[2] > m) m = semi[2];
  if (!(radius == m)) return ShapeFault::bounding_radius;
  return ShapeFault::none;
}

// A body's shape as the narrow phase reads it (mixed scenes only; index = body index, as the spheres):
// kind, semi-axes and the orientation quaternion in Real (the rows as given, rounded once); the narrow
// phase builds the rotation from it where it needs one (ellipsoid_of, core/shape_narrow.hpp). 32 bytes
// in fp32 and 64 in fp64 (a packed rotation matrix would make them 64 and 112): the narrow stage
// gathers two per candidate at random. fp32's rotation is built in float from the rounded quaternion;
// fp64's from the double quaternion. Spheres: kind only (the rest zero).
template <class Real>
struct alignas(16) PackedShape {
  Quat<Real> orientation;
  Vec3<Real> semi_axes;
  std::uint32_t kind;  // Shape
};
static_assert(sizeof(PackedShape<float>) == 32 && sizeof(PackedShape<double>) == 64);

// The bodies' shape rows as given, doubles by body index (semi-axes x y z at 3i, orientation w x y z
// at 4i; read for ellipsoids only): what pack_shape packs. The narrow stage of fp32 reads them again
// for the pairs it solves in fp64 (core/shape_narrow.hpp: ShapeDecide); fp64 and mixed leave them null.
struct ShapeRowsView {
  const double* semi_axes = nullptr;
  const double* orientation = nullptr;
};

template <class Real>
CG_HD PackedShape<Real> pack_shape(std::uint8_t kind, const double* semi, const double* q) {
  PackedShape<Real> p{};
  p.kind = kind;
  if (kind != static_cast<std::uint8_t>(Shape::ellipsoid)) return p;
  p.orientation = {static_cast<Real>(q[0]), static_cast<Real>(q[1]), static_cast<Real>(q[2]),
                   static_cast<Real>(q[3])};
  p.semi_axes = {static_cast<Real>(semi[0]), static_cast<Real>(semi[1]), static_cast<Real>(semi[2])};
  return p;
}

}  // namespace cg
