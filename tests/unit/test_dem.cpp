// Granular dynamics (kernels/dem.hpp) against analytic solutions, one test body per backend (the CUDA
// cases skip, visibly, without a GPU; the CUDA backend is compared with the CPU bit for bit in
// test_dem_backends.cpp, the fixed-order sums in test_dem_sums.cpp):
//   - the damping of a restitution: the dimensionless collision gives back the restitution asked for;
//   - a sphere dropped on a wall rebounds with the set restitution (0.3, 0.7, 0.9) within 1 %;
//   - two equal spheres head on (elastic): Hertz's contact duration and largest overlap within 2 %;
//   - restitution 1, no friction, no gravity, bodies in a closed box: total energy drifts < 0.1 % over
//     10^4 steps (1000 spheres, scaled down from "a few thousand" to keep CI short; 150 spinning
//     ellipsoids);
//   - an oblique impact on a wall: in gross sliding (incidence above the (7/2) μ (1 + e) limit) the
//     rebound's tangential velocity and spin are Walton's, v_t − μ(1+e)v_n and 5μ(1+e)v_n/(2R), within
//     2 % (Chung & Ooi 2011, test 6: aluminium oxide, R = 2.55 mm, 3.9 m/s); below that limit (the
//     contact sticks for part of the impact, where the published curves depend on the tangential
//     model) only what holds for any model: the tangential impulse within Coulomb's bound and no
//     energy gained;
//   - static friction at size ratios 3 and 10: a sphere held between two fixed spheres against gravity
//     hangs still, sunk and turned by what the two tangential springs need;
//   - a single ellipsoid on a plane settles on its longest axis (its shortest semi-axis vertical);
//   - a heap of spheres is steeper with more friction (the angle of repose rises with it).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "backends.hpp"
#include "core/dem_step.hpp"
#include "core/dem_sum.hpp"
#include "dem.hpp"
#include "dem_physics.hpp"

namespace cg::test {
namespace {

using dem::Material;
using dem::Wall;
using dem::WallKind;

DemBodies one_sphere(Vec3<double> p, double r, Vec3<double> v, Vec3<double> w = {0, 0, 0}) {
  DemBodies b;
  b.position = {p};
  b.radius = {r};
  b.velocity = {v};
  b.angular_velocity = {w};
  return b;
}

DemOptions options_on(Backend backend, const Material& m, double dt) {
  DemOptions o;
  o.material = m;
  o.dt = dt;
  o.engine.backend = backend;
  o.engine.threads = 2;
  return o;
}

TYPED_TEST_SUITE(DemPhysics, BackendTypes, BackendTypeNames);

TEST(DemDamping, RestitutionRoundTrip) {
  EXPECT_EQ(damping_for_restitution(1.0), 0.0);
  EXPECT_NEAR(restitution_for_damping(0.0), 1.0, 1e-6);
  double last = 1;
  for (double e : {0.95, 0.9, 0.7, 0.5, 0.3, 0.1}) {
    const double a = damping_for_restitution(e);
    EXPECT_GT(a, 0);
    EXPECT_NEAR(restitution_for_damping(a), e, 1e-7) << "e " << e;
    EXPECT_LT(restitution_for_damping(a), last) << "more damping, less restitution";
    last = restitution_for_damping(a);
  }
  EXPECT_THROW(damping_for_restitution(0), UsageError);
  EXPECT_THROW(damping_for_restitution(1.5), UsageError);
}

// The rebound velocity of a sphere that meets the floor at 1 m/s (no gravity: the velocities before
// and after the contact are the collision's own).
double rebound(Backend backend, double e, bool synchronized) {
  Material m;
  m.young = 1e8;
  m.restitution = e;
  m.friction = 0.3;
  const double r = 0.01;
  DemBodies b = one_sphere({0, 0, r + 0.0005}, r, {0, 0, -1});
  const double dt = time_step_limits(b, m, 1.0).automatic;
  DemOptions o = options_on(backend, m, dt);
  o.synchronized = synchronized;
  o.walls = {plane({0, 0, 0}, {0, 0, 1})};
  Simulation<double> s(b, o);
  double vz = -1;
  for (int step = 0; step < 20000; ++step) {
    s.run(1);
    const DemBodies now = s.bodies();
    vz = now.velocity[0].z;
    if (vz > 0 && now.position[0].z > r + 1e-6) break;  // left the floor
  }
  return vz;
}

TYPED_TEST(DemPhysics, SphereReboundsWithTheRestitution) {
  for (double e : {0.3, 0.7, 0.9}) {
    const double v = rebound(TypeParam::backend, e, true);
    EXPECT_NEAR(v / e, 1.0, 0.01) << "restitution " << e << ": rebound " << v << " m/s";
  }
}

// Two equal spheres head on, elastic: Hertz's largest overlap δ = (5 m* v² / (4 K))^{2/5} and duration
// 2.94328 δ / v (v the approach speed, K = 4/3 E* √R*), within 2 %; the contact's start and end are
// interpolated between steps.
TYPED_TEST(DemPhysics, HertzHeadOnDurationAndOverlap) {
  const Backend backend = TypeParam::backend;
  Material m;
  m.young = 5e7;
  m.poisson = 0.25;
  m.density = 2000;
  m.restitution = 1;
  m.friction = 0;
  const double r = 0.02, v = 0.5;  // each at v/2
  DemBodies b;
  b.position = {{-r - 1e-4, 0, 0}, {r + 1e-4, 0, 0}};
  b.radius = {r, r};
  b.velocity = {{v / 2, 0, 0}, {-v / 2, 0, 0}};
  const double e_star = m.young / (2 * (1 - m.poisson * m.poisson));
  const double mass = m.density * 4.0 / 3.0 * dem::kPi * r * r * r;
  const double m_star = mass / 2, r_star = r / 2, k = 4.0 / 3.0 * e_star * std::sqrt(r_star);
  const double delta_max = std::pow(5 * m_star * v * v / (4 * k), 0.4);
  const double duration = 2.94328 * delta_max / v;
  const double dt = duration / 400;
  Simulation<double> s(b, options_on(backend, m, dt));
  double prev_gap = 2e-4, start = -1, end = -1, deepest = 0;
  for (int step = 1; step < 4000 && end < 0; ++step) {
    s.run(1);
    const DemBodies now = s.bodies();
    const double gap = (now.position[1].x - now.position[0].x) - 2 * r;
    const double t = step * dt;
    if (start < 0 && gap < 0) start = t - dt * gap / (gap - prev_gap);  // where the gap crossed 0
    if (start >= 0 && gap > 0) end = t - dt * gap / (gap - prev_gap);
    deepest = std::max(deepest, -gap);
    prev_gap = gap;
  }
  ASSERT_GT(start, 0);
  ASSERT_GT(end, start);
  EXPECT_NEAR((end - start) / duration, 1.0, 0.02) << "contact duration " << end - start << " s";
  EXPECT_NEAR(deepest / delta_max, 1.0, 0.02) << "largest overlap " << deepest;
}

// Elastic, frictionless bodies in a closed box, no gravity: the total energy (kinetic, with rotation,
// + elastic) drifts by less than 0.1 % over 10^4 steps. Spheres (1000) or ellipsoids (150, semi-axes
// r, 0.6 r, 0.4 r, spinning: their contacts exchange rotation and translation).
void elastic_gas(Backend backend, bool ellipsoids) {
  Material m;
  m.young = 1e7;
  m.density = 1000;
  m.restitution = 1;
  m.friction = 0;
  std::mt19937_64 rng(ellipsoids ? 4402 : 4401);
  std::uniform_real_distribution<double> u(0, 1);
  const int n = ellipsoids ? 150 : 1000;
  const double r = 0.01, box = ellipsoids ? 0.14 : 0.4;  // volume fraction ≈ 0.23 · 0.24 / 6.5 %
  DemBodies b;
  for (int i = 0; i < n; ++i) {
    Vec3<double> p;
    bool ok = false;
    while (!ok) {
      p = {r + (box - 2 * r) * u(rng), r + (box - 2 * r) * u(rng), r + (box - 2 * r) * u(rng)};
      ok = true;
      for (const auto& q : b.position)
        if (dot(p - q, p - q) < 4.4 * r * r) ok = false;
    }
    b.position.push_back(p);
    b.radius.push_back(r);
    b.velocity.push_back({u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5});
    if (ellipsoids) {
      b.angular_velocity.push_back({20 * (u(rng) - 0.5), 20 * (u(rng) - 0.5), 20 * (u(rng) - 0.5)});
      b.shape.push_back(Shape::ellipsoid);
      b.semi_axes.push_back({r, 0.6 * r, 0.4 * r});
      Quat<double> q{u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5};
      const double len = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
      b.orientation.push_back({q.w / len, q.x / len, q.y / len, q.z / len});
    }
  }
  DemOptions o = options_on(backend, m, time_step_limits(b, m, 1.0).automatic);
  o.walls = {plane({0, 0, 0}, {1, 0, 0}),    plane({box, 0, 0}, {-1, 0, 0}), plane({0, 0, 0}, {0, 1, 0}),
             plane({0, box, 0}, {0, -1, 0}), plane({0, 0, 0}, {0, 0, 1}),    plane({0, 0, box}, {0, 0, -1})};
  o.engine.skin = 0.1 * r;
  Simulation<double> s(b, o);
  const double e0 = s.energies().total();
  double worst = 0;
  std::size_t touching = 0;
  for (int chunk = 0; chunk < 100; ++chunk) {
    s.run(100);
    worst = std::max(worst, std::abs(s.energies().total() - e0) / e0);
    touching += s.contact_count();
  }
  EXPECT_LT(worst, 1e-3) << "largest relative drift of the total energy";
  EXPECT_GT(touching, 100u) << "the bodies collide";
  EXPECT_GT(s.engine_stats().candidate_reuses, 1000u) << "the skin keeps most candidate lists";
}

TYPED_TEST(DemPhysics, ElasticGasConservesEnergy) { elastic_gas(TypeParam::backend, false); }
TYPED_TEST(DemPhysics, ElasticEllipsoidGasConservesEnergy) { elastic_gas(TypeParam::backend, true); }

// Oblique impact on a wall (Chung & Ooi 2011, test 6): aluminium oxide sphere, 3.9 m/s.
struct Impact {
  double vt, vn, spin;
};
Impact oblique(Backend backend, double degrees) {
  Material m;
  m.young = 3.8e11;
  m.poisson = 0.23;
  m.density = 4000;
  m.restitution = 0.98;
  m.friction = 0.092;
  const double r = 0.00255, speed = 3.9, a = degrees * dem::kPi / 180;
  DemBodies b = one_sphere({0, 0, r + 1e-5}, r, {speed * std::sin(a), 0, -speed * std::cos(a)});
  DemOptions o = options_on(backend, m, time_step_limits(b, m, speed).automatic / 2);
  o.walls = {plane({0, 0, 0}, {0, 0, 1})};
  Simulation<double> s(b, o);
  for (int step = 0; step < 100000; ++step) {
    s.run(1);
    const DemBodies now = s.bodies();
    if (now.velocity[0].z > 0 && now.position[0].z > r + 1e-7)
      return {now.velocity[0].x, now.velocity[0].z, now.angular_velocity[0].y};
  }
  return {0, 0, 0};
}

TYPED_TEST(DemPhysics, ObliqueImpactFollowsWaltonInGrossSliding) {
  const double mu = 0.092, e = 0.98, r = 0.00255, speed = 3.9;
  for (double degrees : {60.0, 80.0}) {
    const double a = degrees * dem::kPi / 180;
    const double vt = speed * std::sin(a), vn = speed * std::cos(a);
    const Impact got = oblique(TypeParam::backend, degrees);
    EXPECT_NEAR(got.vn / (e * vn), 1.0, 0.02) << degrees << "°: normal rebound";
    const double want_vt = vt - mu * (1 + e) * vn, want_spin = 2.5 * mu * (1 + e) * vn / r;
    EXPECT_NEAR(got.vt / want_vt, 1.0, 0.02) << degrees << "°: tangential rebound " << got.vt;
    EXPECT_NEAR(got.spin / want_spin, 1.0, 0.02) << degrees << "°: spin " << got.spin;
  }
  for (double degrees : {5.0, 20.0}) {  // below the gross-sliding limit (32.5°)
    const double a = degrees * dem::kPi / 180;
    const double vt = speed * std::sin(a), vn = speed * std::cos(a);
    const Impact got = oblique(TypeParam::backend, degrees);
    EXPECT_LE(vt - got.vt, 1.0001 * mu * (1 + e) * vn)
        << degrees << "°: the tangential impulse is within Coulomb's";
    const double inertia = 0.4 * r * r;  // per unit mass
    const double before = vt * vt + vn * vn,
                 after = got.vt * got.vt + got.vn * got.vn + inertia * got.spin * got.spin;
    EXPECT_LT(after, before) << degrees << "°: no energy gained";
    EXPECT_GT(got.spin, 0.0) << degrees << "°: friction spins it forward";
  }
}

// A sphere (radius 1) held by friction between two fixed spheres of radii 3 and 10 on either side,
// against gravity: it settles still, its tangential forces each carry half its weight (torques
// balance), so it sinks by s = (ξ₁ + ξ₂)/2 and turns by φ = (ξ₁ − ξ₂)/(2r), ξᵢ = m g / (2 kᵢ) with
// Mindlin's kᵢ = 8 G* √(R*ᵢ δᵢ) (its turn: the integral of its spin).
struct Hanging {
  double sink, want_sink, turn, want_turn, speed;
};
Hanging hanging_sphere(Backend backend, bool synchronized) {
  Material m;
  m.young = 1e8;  // the normal force μ N is 7× the half weight each contact carries
  m.poisson = 0.3;
  m.density = 1000;
  m.restitution = 0.5;
  m.friction = 0.8;
  const double r = 1, r1 = 3, r2 = 10, d1 = 0.02;
  // the right overlap that balances the left's normal force: K₁ δ₁^{3/2} = K₂ δ₂^{3/2}, K ∝ √R*
  const double rs1 = r * r1 / (r + r1), rs2 = r * r2 / (r + r2);
  const double d2 = d1 * std::pow(std::sqrt(rs1 / rs2), 2.0 / 3.0);
  DemBodies b;
  b.position = {{0, 0, 0}, {-(r + r1 - d1), 0, 0}, {r + r2 - d2, 0, 0}};
  b.radius = {r, r1, r2};
  b.fixed = {0, 1, 1};
  const double g = 9.81;
  DemOptions o = options_on(backend, m, time_step_limits(b, m, 1.0).automatic);
  o.synchronized = synchronized;
  o.gravity = {0, 0, -g};
  Simulation<double> s(b, o);
  Hanging h{};
  for (int step = 0; step < 20000; ++step) {
    s.run(1);
    h.turn += s.bodies().angular_velocity[0].y * o.dt;
  }
  const DemBodies now = s.bodies();
  const double mass = m.density * 4.0 / 3.0 * dem::kPi * r * r * r;
  const double g_star = m.young / (4 * (2 - m.poisson) * (1 + m.poisson));
  const double k1 = 8 * g_star * std::sqrt(rs1 * d1), k2 = 8 * g_star * std::sqrt(rs2 * d2);
  const double xi1 = mass * g / (2 * k1), xi2 = mass * g / (2 * k2);
  h.sink = -now.position[0].z;
  h.want_sink = 0.5 * (xi1 + xi2);
  h.want_turn = 0.5 * (xi1 - xi2) / r;
  h.speed = std::sqrt(dot(now.velocity[0], now.velocity[0]));
  return h;
}

TYPED_TEST(DemPhysics, StaticFrictionHoldsAtSizeRatiosThreeAndTen) {
  const Hanging h = hanging_sphere(TypeParam::backend, true);
  EXPECT_NEAR(h.sink / h.want_sink, 1.0, 0.02) << "sink " << h.sink << " want " << h.want_sink;
  EXPECT_NEAR(std::abs(h.turn) / std::abs(h.want_turn), 1.0, 0.05)
      << "turn " << h.turn << " want " << h.want_turn;
  EXPECT_LT(h.speed, 1e-3 * h.want_sink) << "it hangs still";
}

// A single ellipsoid (semi-axes 2, 1, 0.5) dropped tilted on a floor comes to rest lying on its
// longest axis: its shortest axis vertical, its centre 0.5 above the floor (less the contact's
// overlap). Rolling friction stops its spin about the vertical (a point contact has no other).
TYPED_TEST(DemPhysics, EllipsoidSettlesOnItsLongestAxis) {
  const Backend backend = TypeParam::backend;
  Material m;
  m.young = 1e8;
  m.density = 1000;
  m.restitution = 0.3;
  m.friction = 0.5;
  m.rolling_friction = 0.1;
  DemBodies b;
  b.position = {{0, 0, 2.5}};
  b.radius = {2};
  b.shape = {Shape::ellipsoid};
  b.semi_axes = {{2, 1, 0.5}};
  const double c = std::cos(0.6), s = std::sin(0.6);  // tilted about an axis in the floor's plane
  b.orientation = {{c, s * 0.6, s * 0.8, 0}};
  DemOptions o = options_on(backend, m, time_step_limits(b, m, 7.0).automatic);
  o.gravity = {0, 0, -9.81};
  o.walls = {plane({0, 0, 0}, {0, 0, 1})};
  Simulation<double> sim(b, o);
  const double steps_per_second = 1 / o.dt;
  sim.run(static_cast<std::uint64_t>(10 * steps_per_second));
  const DemBodies now = sim.bodies();
  const Vec3<double> shortest = column(rotation_matrix(now.orientation[0]), 2);
  EXPECT_GT(std::abs(shortest.z), 0.999) << "the shortest axis is vertical";
  EXPECT_NEAR(now.position[0].z, 0.5, 0.01) << "resting on its flat side";
  EXPECT_LT(std::sqrt(dot(now.velocity[0], now.velocity[0])), 1e-3) << "at rest";
}

// A heap: 400 spheres (radii 4.5–5.5 mm) released from a narrow column onto a floor spread into a
// heap whose slope rises with the sliding friction (the angle of repose; rolling friction 0.1 in both,
// so that spheres do not roll away). The slope is atan(height / base radius): the height of the
// highest tenth of the bodies over the floor, the radius that holds 90 % of them about the heap's
// axis. A few seconds per backend on the CPU.
double heap_slope_degrees(Backend backend, double friction) {
  std::mt19937_64 rng(4421);
  std::uniform_real_distribution<double> u(0, 1);
  DemBodies b;
  const int side = 6;
  const double s = 0.0115;
  for (int i = 0; i < 400; ++i) {
    const double jitter_x = 0.0004 * (u(rng) - 0.5), jitter_y = 0.0004 * (u(rng) - 0.5);
    b.position.push_back({(i % side - 2.5) * s + jitter_x, ((i / side) % side - 2.5) * s + jitter_y,
                          (i / (side * side) + 1) * s});
    b.radius.push_back(0.0045 + 0.001 * u(rng));
  }
  Material m;
  m.young = 1e6;
  m.density = 2500;
  m.restitution = 0.3;
  m.friction = friction;
  m.rolling_friction = 0.1;
  DemOptions o = options_on(backend, m, time_step_limits(b, m, 2.0).automatic);
  o.gravity = {0, 0, -9.81};
  o.walls = {plane({0, 0, 0}, {0, 0, 1})};
  o.engine.skin = 0.0005;
  Simulation<double> sim(b, o);
  sim.run(static_cast<std::uint64_t>(1.5 / o.dt));
  const DemBodies now = sim.bodies();
  Vec3<double> centre{0, 0, 0};
  for (const auto& p : now.position) centre = centre + (1.0 / double(now.size())) * p;
  std::vector<double> heights, radii;
  for (const auto& p : now.position) {
    heights.push_back(p.z);
    radii.push_back(std::hypot(p.x - centre.x, p.y - centre.y));
  }
  std::sort(heights.begin(), heights.end());
  std::sort(radii.begin(), radii.end());
  double top = 0;
  for (std::size_t k = heights.size() * 9 / 10; k < heights.size(); ++k) top += heights[k];
  top /= double(heights.size() - heights.size() * 9 / 10);
  const double base = radii[radii.size() * 9 / 10];
  double speed = 0;
  for (const auto& v : now.velocity) speed += std::sqrt(dot(v, v)) / double(now.size());
  EXPECT_LT(speed, 0.02) << "friction " << friction << ": the heap has settled (mean speed, m/s)";
  return std::atan2(top, base) * 180 / dem::kPi;
}

TYPED_TEST(DemPhysics, HeapSlopeRisesWithFriction) {
  const double low = heap_slope_degrees(TypeParam::backend, 0.1);
  const double high = heap_slope_degrees(TypeParam::backend, 0.7);
  // a collapsing column, not a slow pour: low slopes, but friction must make the heap clearly steeper
  // (at friction 0 the spheres spread to a layer; this heap has about 1° at 0.1 and 5.5° at 0.7)
  EXPECT_GT(high, 2 * low) << "slope " << low << "° at friction 0.1, " << high << "° at 0.7";
  EXPECT_GT(high - low, 2.0) << "slope " << low << "° at friction 0.1, " << high << "° at 0.7";
  EXPECT_GT(low, 0.3) << "even low friction leaves a heap";
}

}  // namespace
}  // namespace cg::test
