#pragma once
// Narrow phase for sphere pairs, exactly as docs/FORMAT.md §3 (Bullet's btSphereSphereCollisionAlgorithm
// semantics), shared by both backends. sphere_contact_row: points in the engine's local frame, moved
// to the world by to_world (fp32); world_sphere_row: from the world doubles (fp64, mixed).
#include <limits>
#include <type_traits>

#include "core/config.hpp"
#include "core/contact_fields.hpp"
#include "core/vec3.hpp"

#if !defined(__CUDA_ARCH__)
#include <cmath>
#endif

namespace cg {

template <class Real>
CG_HD Real cg_sqrt(Real v) {
#if defined(__CUDA_ARCH__)
  return ::sqrt(v);  // IEEE correctly rounded (nvcc -prec-sqrt=true, the default)
#else
  return std::sqrt(v);
#endif
}

// Contact test: d <= ra + rb (touching counts), evaluated without a square root.
template <class Real>
CG_HD bool spheres_touch(const Sphere<Real>& a, const Sphere<Real>& b) {
  Real dx = a.x - b.x, dy = a.y - b.y, dz = a.z - b.z;
  Real s = a.r + b.r;
  return dx * dx + dy * dy + dz * dz <= s * s;
}

template <class Real>
struct ContactGeometry {
  Vec3<Real> position_on_a, position_on_b, normal_on_b;  // local frame; normal from B to A
  Real distance;                                         // negative when overlapping
};

template <class Real>
CG_HD ContactGeometry<Real> sphere_sphere_contact(const Sphere<Real>& a, const Sphere<Real>& b) {
  Vec3<Real> d = a.centre() - b.centre();
  Real len = cg_sqrt(dot(d, d));
  Vec3<Real> n;
  if (len > std::numeric_limits<Real>::epsilon()) {
    n = (Real(1) / len) * d;
  } else {
    n = {Real(1), Real(0), Real(0)};  // coincident centres: Bullet's choice
  }
  ContactGeometry<Real> c;
  c.normal_on_b = n;
  c.distance = len - (a.r + b.r);
  c.position_on_b = b.centre() + b.r * n;
  c.position_on_a = a.centre() - a.r * n;
  return c;
}

// Bullet's btPlaneSpace1: the tangent basis (lateralFrictionDir1/2) of a unit normal.
template <class Real>
CG_HD void plane_space(Vec3<Real> n, Vec3<Real>& dir1, Vec3<Real>& dir2) {
  const Real sqrt_half = Real(0.7071067811865475244);
  if ((n.z < 0 ? -n.z : n.z) > sqrt_half) {
    Real a = n.y * n.y + n.z * n.z;
    Real k = Real(1) / cg_sqrt(a);
    dir1 = {Real(0), -n.z * k, n.y * k};
    dir2 = {a * k, -n.x * dir1.z, n.x * dir1.y};
  } else {
    Real a = n.x * n.x + n.y * n.y;
    Real k = Real(1) / cg_sqrt(a);
    dir1 = {-n.y * k, n.x * k, Real(0)};
    dir2 = {-n.z * dir1.y, n.z * dir1.x, a * k};
  }
}

// A local-frame point back in the world frame: origin (double) + local, rounded once to Real.
template <class Real>
CG_HD Vec3<Real> to_world(const Vec3<double>& origin, const Vec3<Real>& local) {
  return {static_cast<Real>(origin.x + double(local.x)), static_cast<Real>(origin.y + double(local.y)),
          static_cast<Real>(origin.z + double(local.z))};
}

// One row of the contact output (docs/FORMAT.md §2), world frame: ContactRow (core/contact_fields.hpp). The
// optional members are computed only when asked for (Fields::full): local points (R = identity for
// spheres) and Bullet's friction directions. The ids are set by the narrow stage.
template <class Real>
CG_HD ContactRow<Real> sphere_contact_row(const Sphere<Real>& a, const Sphere<Real>& b,
                                          const Vec3<double>& origin, bool full) {
  const ContactGeometry<Real> c = sphere_sphere_contact(a, b);
  ContactRow<Real> row{};
  row.position_on_a = to_world(origin, c.position_on_a);
  row.position_on_b = to_world(origin, c.position_on_b);
  row.normal_on_b = c.normal_on_b;
  row.distance = c.distance;
  if (full) {
    row.local_point_a = c.position_on_a - a.centre();
    row.local_point_b = c.position_on_b - b.centre();
    plane_space(c.normal_on_b, row.lateral_friction_dir1, row.lateral_friction_dir2);
  }
  return row;
}

// The row of a sphere pair from its WORLD centres and radii (fp64 and mixed): d = a − b is the
// difference of two world doubles (exact when they are within a factor 2 of each other, Sterbenz),
// the points are the world centres plus their offsets (one rounding each), and the local points are
// the offsets themselves (−ra·n, rb·n: R = identity), with no cancellation against the centres.
CG_HD ContactRow<double> world_sphere_row(const Sphere<double>& a, const Sphere<double>& b, bool full) {
  const ContactGeometry<double> c = sphere_sphere_contact(a, b);
  ContactRow<double> row{};
  row.position_on_a = c.position_on_a;
  row.position_on_b = c.position_on_b;
  row.normal_on_b = c.normal_on_b;
  row.distance = c.distance;
  if (full) {
    row.local_point_a = (-a.r) * c.normal_on_b;
    row.local_point_b = b.r * c.normal_on_b;
    plane_space(c.normal_on_b, row.lateral_friction_dir1, row.lateral_friction_dir2);
  }
  return row;
}

// A row rounded to another real type, field by field (ids unchanged).
template <class To, class From>
CG_HD ContactRow<To> row_cast(const ContactRow<From>& in, bool full) {
  ContactRow<To> out{};
  zip_contact_fields(out, in, full, [](auto, auto& o, const auto& i) {
    using T = std::remove_reference_t<decltype(o)>;
    if constexpr (std::is_same_v<T, Vec3<To>>)
      o = vec_cast<To>(i);
    else
      o = static_cast<T>(i);
  });
  return out;
}

}  // namespace cg
