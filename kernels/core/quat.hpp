#pragma once
// Quaternions and 3×3 rotation matrices for the ellipsoid narrow phase, shared by host and device.
// A quaternion (w, x, y, z) rotates body-local to world (docs/FORMAT.md §1). The matrix is built once per
// body, not once per pair: R v takes a local vector to the world, Rᵀ v (mul_transpose) a world vector
// to the body frame.
#include "core/config.hpp"
#include "core/vec3.hpp"

namespace cg {

template <class Real>
struct Quat {
  Real w, x, y, z;
};

// Rows of R: R v = (r0·v, r1·v, r2·v).
template <class Real>
struct Mat3 {
  Vec3<Real> r0, r1, r2;
};

template <class Real>
CG_HD Mat3<Real> identity_matrix() {
  return {{Real(1), Real(0), Real(0)}, {Real(0), Real(1), Real(0)}, {Real(0), Real(0), Real(1)}};
}

// The rotation of q / |q|: the input need not be exactly unit (file data are rounded), the matrix is
// orthonormal to rounding either way. Precondition: q ≠ 0 (the input check rejects it); a zero
// quaternion gives the identity rather than NaNs.
template <class Real>
CG_HD Mat3<Real> rotation_matrix(Quat<Real> q) {
  const Real n2 = q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z;
  if (!(n2 > Real(0))) return identity_matrix<Real>();
  const Real s = Real(2) / n2;
  const Real xx = s * q.x * q.x, yy = s * q.y * q.y, zz = s * q.z * q.z;
  const Real xy = s * q.x * q.y, xz = s * q.x * q.z, yz = s * q.y * q.z;
  const Real wx = s * q.w * q.x, wy = s * q.w * q.y, wz = s * q.w * q.z;
  return {{Real(1) - (yy + zz), xy - wz, xz + wy},
          {xy + wz, Real(1) - (xx + zz), yz - wx},
          {xz - wy, yz + wx, Real(1) - (xx + yy)}};
}

// R v: body frame → world.
template <class Real>
CG_HD Vec3<Real> mul(const Mat3<Real>& m, Vec3<Real> v) {
  return {dot(m.r0, v), dot(m.r1, v), dot(m.r2, v)};
}

// Rᵀ v: world → body frame.
template <class Real>
CG_HD Vec3<Real> mul_transpose(const Mat3<Real>& m, Vec3<Real> v) {
  return {m.r0.x * v.x + m.r1.x * v.y + m.r2.x * v.z, m.r0.y * v.x + m.r1.y * v.y + m.r2.y * v.z,
          m.r0.z * v.x + m.r1.z * v.y + m.r2.z * v.z};
}

// Column k of R: the world direction of the body's local axis k (0 = x, 1 = y, 2 = z).
template <class Real>
CG_HD Vec3<Real> column(const Mat3<Real>& m, int k) {
  return k == 0 ? Vec3<Real>{m.r0.x, m.r1.x, m.r2.x}
                : (k == 1 ? Vec3<Real>{m.r0.y, m.r1.y, m.r2.y} : Vec3<Real>{m.r0.z, m.r1.z, m.r2.z});
}

// q v q*, through the matrix.
template <class Real>
CG_HD Vec3<Real> rotate(Quat<Real> q, Vec3<Real> v) {
  return mul(rotation_matrix(q), v);
}

}  // namespace cg
