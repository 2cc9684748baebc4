#pragma once
// The contact force law of the granular dynamics (contactgrid simulate), shared by both backends:
// Hertz–Mindlin with viscous damping from a coefficient of restitution, a tangential spring carried
// across steps (the contact identity: core/history.hpp) with a Coulomb limit, and an optional
// constant rolling-resistance torque. Small host/device functions over one contact, in the style of
// HOOMD's evaluators; double throughout, with +, −, ×, ÷ and √ only (IEEE on both backends, no FMA
// contraction), so the CPU and CUDA forces are the same bits.
//
// Normal force on A (n points from B to A, overlap δ = −distance > 0, approach rate δ̇):
//   F_n = max(0, K δ^{3/2} + α √(m* K) δ^{1/4} δ̇),   K = 4/3 E* √R*
// — Hertz's elastic force and the damping of Tsuji et al. (1992), whose coefficient of restitution
// does not depend on the impact speed. In units where m* = K = v₀ = 1 the collision is
// x'' = −x^{3/2} − α x^{1/4} x', so the restitution is a function of α alone: damping_for_restitution
// (host) inverts it numerically, so that a collision rebounds with the restitution asked for, not
// with the linear-spring approximation many codes use. The max(0, ·) keeps a contact from pulling.
// Tangential force (Mindlin's no-slip stiffness S_t = 8 G* √(R* δ), damping of the same form):
//   ξ ← ξ projected into the tangent plane + v_t Δt;   F_t = −S_t ξ − γ_t v_t, |F_t| ≤ μ F_n
// (when the limit binds, ξ is the spring's share of the limited force, as LAMMPS and LIGGGHTS do).
#include <cstdint>

#include "core/config.hpp"
#include "core/contact.hpp"
#include "core/vec3.hpp"

namespace cg::dem {

// The one material (command line): E (Young's modulus), ν, density, restitution e ∈ (0, 1],
// friction μ ≥ 0, rolling friction μ_r ≥ 0. Consistent units of the user's choice (SI in the docs).
struct Material {
  double young = 1e7, poisson = 0.3, density = 2500, restitution = 0.5, friction = 0.5, rolling_friction = 0;
};

// The constants a contact of two bodies of the material (or of a body and a wall of it) needs.
struct ContactLaw {
  double e_star = 0;  // E* = E / (2 (1 − ν²))
  double g_star = 0;  // G* = E / (4 (2 − ν)(1 + ν))
  double alpha = 0;   // the damping of the restitution (damping_for_restitution)
  double friction = 0, rolling_friction = 0;
};

// The two bodies' properties a contact reads: effective radius R* and mass m* (a wall, or a fixed
// body: the other body's mass; both fixed: no force matters, the first's).
struct Pair {
  double radius = 0, mass = 0;
};
CG_HD Pair pair_of(double ra, double ma, bool fa, double rb, double mb, bool fb) {
  const double m = fa ? mb : (fb ? ma : ma * mb / (ma + mb));
  return {ra * rb / (ra + rb), m};
}

CG_HD double norm(Vec3<double> v) { return cg_sqrt(dot(v, v)); }

// ξ turned into the plane ⊥ n with its length kept (the frame of a contact turns with its normal;
// Luding 2008). A ξ along n is dropped.
CG_HD Vec3<double> into_plane(Vec3<double> xi, Vec3<double> n) {
  const double before = dot(xi, xi);
  if (!(before > 0)) return {0, 0, 0};
  const Vec3<double> t = xi - dot(xi, n) * n;
  const double after = dot(t, t);
  if (!(after > 0)) return {0, 0, 0};
  return cg_sqrt(before / after) * t;
}

// What the force law needs of one contact at this step.
struct ContactInput {
  Vec3<double> normal;       // n, from B to A, unit, at the step's positions
  Vec3<double> half_normal;  // n at the half step (the tangential increment's plane); = normal if new
  double overlap;            // δ = −distance (> 0 in contact)
  Vec3<double> v_half;       // relative velocity of the contact point (A − B) at the half step
  Vec3<double> v_sync;       // the same at the step (synchronised: the damping's)
  Vec3<double> w_rel;        // ω_A − ω_B at the step (rolling resistance)
  double dt;
};

// One contact's output: force on A (B gets −force), rolling torque on A (B gets −torque), the new
// spring ξ, and the elastic energy stored (normal 2/5 K δ^{5/2} + tangential ½ S_t |ξ|²).
struct ContactOutput {
  Vec3<double> force, rolling_torque, xi;
  double energy;
};

// The force law (file comment). `xi` is the pair's spring from the previous step (zero when new).
// `inertia`: the pair's effective moment of inertia (rolling resistance's cap: it never reverses the
// relative spin within a step).
CG_HD ContactOutput contact_force(const ContactLaw& law, const Pair& p, double inertia, const ContactInput& c,
                                  Vec3<double> xi) {
  ContactOutput out{{0, 0, 0}, {0, 0, 0}, {0, 0, 0}, 0};
  const double d = c.overlap;
  if (!(d > 0)) return out;  // touching: no force, the spring restarts
  const double sd = cg_sqrt(d), qd = cg_sqrt(sd);
  const double sr = cg_sqrt(p.radius);
  const double k = (4.0 / 3.0) * law.e_star * sr;              // K
  const double damp_n = law.alpha * cg_sqrt(p.mass * k) * qd;  // α √(m* K) δ^{1/4}
  const double rate = -dot(c.v_sync, c.normal);                // δ̇
  double fn = k * d * sd + damp_n * rate;
  if (!(fn > 0)) fn = 0;
  // tangential: Mindlin's stiffness, the increment over the step at the half step's plane
  const double st = 8.0 * law.g_star * sr * sd;
  const double damp_t = law.alpha * cg_sqrt(p.mass * st * (2.0 / 3.0));
  const Vec3<double> vt_half = c.v_half - dot(c.v_half, c.half_normal) * c.half_normal;
  xi = into_plane(into_plane(xi, c.half_normal) + c.dt * vt_half, c.normal);
  const Vec3<double> vt = c.v_sync - dot(c.v_sync, c.normal) * c.normal;
  Vec3<double> ft = (-st) * xi - damp_t * vt;
  const double limit = law.friction * fn, ft2 = dot(ft, ft);
  if (ft2 > limit * limit) {
    const double scale = ft2 > 0 ? limit / cg_sqrt(ft2) : 0;
    ft = scale * ft;
    xi = st > 0 ? (-1.0 / st) * (ft + damp_t * vt) : Vec3<double>{0, 0, 0};
  }
  out.force = fn * c.normal + ft;
  out.xi = xi;
  out.energy = 0.4 * k * d * d * sd + 0.5 * st * dot(xi, xi);
  // rolling resistance: a constant torque against the relative spin, at most what stops it
  const double w = norm(c.w_rel);
  if (law.rolling_friction > 0 && w > 0) {
    double m = law.rolling_friction * p.radius * fn;
    const double stop = inertia * w / c.dt;
    if (m > stop) m = stop;
    out.rolling_torque = (-m / w) * c.w_rel;
  }
  return out;
}

// The elastic energy of a contact alone (log): as contact_force's `energy`, from δ and ξ.
CG_HD double contact_energy(const ContactLaw& law, const Pair& p, double overlap, Vec3<double> xi) {
  if (!(overlap > 0)) return 0;
  const double sd = cg_sqrt(overlap), sr = cg_sqrt(p.radius);
  const double k = (4.0 / 3.0) * law.e_star * sr, st = 8.0 * law.g_star * sr * sd;
  return 0.4 * k * overlap * overlap * sd + 0.5 * st * dot(xi, xi);
}

}  // namespace cg::dem
