#pragma once
// Rigid bodies of the granular dynamics, shared by both backends: mass and inertia of spheres and
// ellipsoids, their support (the deepest point along a direction: walls), and the synchronised
// velocity-Verlet step (Vyas, Ottino, Lueptow, Umbanhowar, Comput. Phys. Commun. 310 (2025) 109524):
// every term of a step's force is taken at the same time level — elastic forces at the step's
// positions, damping at the step's velocities (estimated: the half-step velocity plus half a step of
// the last acceleration), the tangential spring's increment at the half step with the half step's
// normal, then turned into the step's tangent plane — where plain velocity Verlet mixes half-step
// velocities with full-step positions, which lets statically held grains creep at size ratios above
// about 3. Double, +, −, ×, ÷, √ only: the CPU and CUDA bodies are the same bits.
//
// One step of a body (x, v, ω or L, q; F, τ the last step's force and torque):
//   kick_drift:  v += Δt/2 F/m, ω += Δt/2 I⁻¹τ (ellipsoids: L += Δt/2 τ), x += Δt v,
//                q turned by ω Δt (ellipsoids: ω at the midpoint of the turn, from L)
//   … contacts at the new positions, forces …
//   kick:        v += Δt/2 F/m, ω += Δt/2 I⁻¹τ (ellipsoids: L += Δt/2 τ, ω from L and q)
#include <cmath>

#include "core/contact.hpp"
#include "core/quat.hpp"
#include "core/shape.hpp"
#include "core/vec3.hpp"

namespace cg::dem {

constexpr double kPi = 3.14159265358979323846;

// Mass and inertia of a body of density ρ: a sphere of radius r, or an ellipsoid of semi-axes
// (a, b, c) (principal moments in its body frame). radius: the radius its contacts use (a sphere's
// own; an ellipsoid's volume-equivalent (abc)^{1/3}). Host only (cbrt is not correctly rounded
// everywhere): the properties are made once and copied to the device.
// fixed: the body does not move (an obstacle: its velocities stay as given, forces on it are
// computed and ignored, and its contacts use the other body's mass alone, as a wall's).
struct BodyProps {
  double mass = 0, inv_mass = 0;
  Vec3<double> inertia{0, 0, 0};  // principal moments, body frame (a sphere: all 2/5 m r²)
  double radius = 0;
  bool fixed = false;
};

inline BodyProps body_props(Shape shape, double radius, Vec3<double> semi_axes, double density) {
  BodyProps p;
  if (shape == Shape::ellipsoid) {
    const double a = semi_axes.x, b = semi_axes.y, c = semi_axes.z;
    p.mass = density * (4.0 / 3.0) * kPi * a * b * c;
    p.inertia = {p.mass * (b * b + c * c) / 5.0, p.mass * (a * a + c * c) / 5.0,
                 p.mass * (a * a + b * b) / 5.0};
    p.radius = std::cbrt(a * b * c);
  } else {
    p.mass = density * (4.0 / 3.0) * kPi * radius * radius * radius;
    const double i = 0.4 * p.mass * radius * radius;
    p.inertia = {i, i, i};
    p.radius = radius;
  }
  p.inv_mass = 1.0 / p.mass;
  return p;
}

// A body's shape where walls touch it: a sphere (centre, radius), or an ellipsoid (centre and
// M = R diag(a², b², c²) Rᵀ, whose support along a unit u is centre + M u / √(uᵀ M u)).
struct BodyShape {
  Vec3<double> centre;
  double radius;  // a sphere's
  bool ellipsoid;
  Vec3<double> m0, m1, m2;  // rows of M (ellipsoids)
};

CG_HD BodyShape body_shape(Shape shape, Vec3<double> centre, double radius, Vec3<double> semi_axes,
                           Quat<double> q) {
  BodyShape s{centre, radius, shape == Shape::ellipsoid, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
  if (s.ellipsoid) {
    const Mat3<double> r = rotation_matrix(q);
    const Vec3<double> a2{semi_axes.x * semi_axes.x, semi_axes.y * semi_axes.y, semi_axes.z * semi_axes.z};
    // M = R diag(a²) Rᵀ: M_ij = Σ_k R_ik a²_k R_jk
    auto row = [&](Vec3<double> ri) {
      const Vec3<double> w{ri.x * a2.x, ri.y * a2.y, ri.z * a2.z};
      return Vec3<double>{dot(w, r.r0), dot(w, r.r1), dot(w, r.r2)};
    };
    s.m0 = row(r.r0);
    s.m1 = row(r.r1);
    s.m2 = row(r.r2);
  }
  return s;
}

// The body's extent along the unit u (its support's offset from the centre along u) and the support
// point itself.
CG_HD double extent(const BodyShape& s, Vec3<double> u) {
  if (!s.ellipsoid) return s.radius;
  const Vec3<double> mu{dot(s.m0, u), dot(s.m1, u), dot(s.m2, u)};
  return cg_sqrt(dot(u, mu));
}
CG_HD Vec3<double> support(const BodyShape& s, Vec3<double> u) {
  if (!s.ellipsoid) return s.centre + s.radius * u;
  const Vec3<double> mu{dot(s.m0, u), dot(s.m1, u), dot(s.m2, u)};
  return s.centre + (1.0 / cg_sqrt(dot(u, mu))) * mu;
}

// The state of a body between steps (world frame). omega: angular velocity; momentum: angular
// momentum (ellipsoids integrate it; a sphere's is I ω); force, torque: the last step's.
struct BodyState {
  Vec3<double> position, velocity, omega, momentum;
  Quat<double> orientation;
  Vec3<double> force, torque;
};

// ω of an ellipsoid from its angular momentum: R I⁻¹ Rᵀ L.
CG_HD Vec3<double> omega_of(Vec3<double> momentum, Quat<double> q, Vec3<double> inertia) {
  const Mat3<double> r = rotation_matrix(q);
  const Vec3<double> l = mul_transpose(r, momentum);
  return mul(r, Vec3<double>{l.x / inertia.x, l.y / inertia.y, l.z / inertia.z});
}

// q turned by the rotation vector θ (world frame), through the Cayley form (1, θ/2)/|(1, θ/2)|: a
// rotation by 2·atan(|θ|/2) = |θ| − |θ|³/12 + …, exact in direction, with no trigonometric call.
CG_HD Quat<double> turned(Quat<double> q, Vec3<double> theta) {
  const double hx = 0.5 * theta.x, hy = 0.5 * theta.y, hz = 0.5 * theta.z;
  // (1, h) ⊗ q
  Quat<double> r{q.w - hx * q.x - hy * q.y - hz * q.z, q.x + hx * q.w + hy * q.z - hz * q.y,
                 q.y - hx * q.z + hy * q.w + hz * q.x, q.z + hx * q.y - hy * q.x + hz * q.w};
  const double n = cg_sqrt(r.w * r.w + r.x * r.x + r.y * r.y + r.z * r.z);
  return {r.w / n, r.x / n, r.y / n, r.z / n};
}

// The first half of a step: half kick with the last force, drift, turn.
CG_HD void kick_drift(BodyState& b, const BodyProps& p, bool ellipsoid, double dt) {
  if (p.fixed) return;
  const double h = 0.5 * dt;
  b.velocity = b.velocity + (h * p.inv_mass) * b.force;
  b.position = b.position + dt * b.velocity;
  if (ellipsoid) {
    b.momentum = b.momentum + h * b.torque;
    // the turn's rate at its midpoint: ω(L, q) half a turn ahead
    const Vec3<double> w0 = omega_of(b.momentum, b.orientation, p.inertia);
    const Quat<double> mid = turned(b.orientation, h * w0);
    b.omega = omega_of(b.momentum, mid, p.inertia);
    b.orientation = turned(b.orientation, dt * b.omega);
  } else {
    b.omega = b.omega + (h / p.inertia.x) * b.torque;
  }
}

// The second half: half kick with the new force (b.force, b.torque set by the step).
CG_HD void kick(BodyState& b, const BodyProps& p, bool ellipsoid, double dt) {
  if (p.fixed) return;
  const double h = 0.5 * dt;
  b.velocity = b.velocity + (h * p.inv_mass) * b.force;
  if (ellipsoid) {
    b.momentum = b.momentum + h * b.torque;
    b.omega = omega_of(b.momentum, b.orientation, p.inertia);
  } else {
    b.omega = b.omega + (h / p.inertia.x) * b.torque;
  }
}

// The velocity and spin a force term sees at the step (synchronised): the half-step values plus half
// a step of the last acceleration (b.force, b.torque still hold the last step's at that point).
CG_HD Vec3<double> synced_velocity(const BodyState& b, const BodyProps& p, double dt) {
  if (p.fixed) return b.velocity;
  return b.velocity + (0.5 * dt * p.inv_mass) * b.force;
}
CG_HD Vec3<double> synced_omega(const BodyState& b, const BodyProps& p, bool ellipsoid, double dt) {
  if (p.fixed) return b.omega;
  if (!ellipsoid) return b.omega + (0.5 * dt / p.inertia.x) * b.torque;
  return omega_of(b.momentum + (0.5 * dt) * b.torque, b.orientation, p.inertia);
}

// Kinetic energy ½ m v² + ½ ω·(I ω) (ellipsoids: ½ ω·L).
CG_HD double kinetic_energy(const BodyState& b, const BodyProps& p, bool ellipsoid) {
  const double rot = ellipsoid ? dot(b.omega, b.momentum) : p.inertia.x * dot(b.omega, b.omega);
  return 0.5 * (p.mass * dot(b.velocity, b.velocity) + rot);
}

}  // namespace cg::dem
