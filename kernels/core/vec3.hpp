#pragma once
// Vec3<Real>: a POD 3-vector usable on host and device. Its layout is three contiguous Reals, so a
// std::vector<Vec3<double>> is exactly the (N, 3) row-major layout of the HDF5 datasets.
#include "core/config.hpp"

namespace cg {

template <class Real>
struct Vec3 {
  Real x, y, z;
};

template <class R>
CG_HD Vec3<R> operator+(Vec3<R> a, Vec3<R> b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
template <class R>
CG_HD Vec3<R> operator-(Vec3<R> a, Vec3<R> b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
template <class R>
CG_HD Vec3<R> operator-(Vec3<R> a) {
  return {-a.x, -a.y, -a.z};
}
template <class R>
CG_HD Vec3<R> operator*(R s, Vec3<R> a) {
  return {s * a.x, s * a.y, s * a.z};
}
template <class R>
CG_HD R dot(Vec3<R> a, Vec3<R> b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <class R>
CG_HD Vec3<R> cross(Vec3<R> a, Vec3<R> b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
template <class R>
CG_HD bool operator==(Vec3<R> a, Vec3<R> b) {
  return a.x == b.x && a.y == b.y && a.z == b.z;
}

template <class To, class From>
CG_HD Vec3<To> vec_cast(Vec3<From> v) {
  return {static_cast<To>(v.x), static_cast<To>(v.y), static_cast<To>(v.z)};
}

// A bounding sphere in the engine's local frame (relative to the grid origin), 16-byte aligned in
// fp32 so a GPU thread reads it with one 128-bit load.
template <class Real>
struct alignas(4 * sizeof(Real)) Sphere {
  Real x, y, z, r;
  CG_HD Vec3<Real> centre() const { return {x, y, z}; }
};

}  // namespace cg
