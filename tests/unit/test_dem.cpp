// Granular dynamics (kernels/dem.hpp) against analytic solutions, one test body per backend (the CUDA
// cases skip, visibly, without a GPU; the CUDA backend is also compared with the CPU bit for bit at the
// end):
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
#include "support/contacts_equal.hpp"

namespace cg::test {
namespace {

using dem::Material;
using dem::Wall;
using dem::WallKind;

Wall plane(Vec3<double> point, Vec3<double> normal) {
  Wall w;
  w.kind = WallKind::plane;
  w.point = point;
  w.normal = normal;
  return w;
}

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

// The physics cases: one test body per backend (CUDA skips, visibly, without a GPU).
template <class B>
class DemPhysics : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(B); }
};
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

namespace cg::test {
namespace {

// CPU = CUDA bit for bit: a pour of spheres and ellipsoids in a box with friction, rolling friction
// and gravity, both precisions; every body's state and every contact (with its history) after each
// block of steps. Skipped, visibly, without a GPU.
// The scene of the comparison: spheres (or spheres and ellipsoids) of radius 0.4 … 0.5 on a lattice of
// pitch 0.95 (ellipsoids: 0.8), so that some lattice neighbours start touching and the contacts (with
// their history) are exercised from the first step; random velocities, gravity, a box open at the top.
struct ComparedScene {
  DemBodies bodies;
  DemOptions options;
};
ComparedScene compared_scene(bool ellipsoids) {
  std::mt19937_64 rng(ellipsoids ? 4411 : 4412);
  std::uniform_real_distribution<double> u(0, 1);
  ComparedScene c;
  DemBodies& b = c.bodies;
  const int side = 8;
  const double pitch = ellipsoids ? 0.8 : 0.95;  // ellipsoids are slimmer (semi-axes r, 0.6r, 0.35r)
  for (int i = 0; i < side * side * 12; ++i) {
    const double r = 0.4 + 0.1 * u(rng);
    b.position.push_back(
        {pitch * (i % side) + 0.6, pitch * ((i / side) % side) + 0.6, pitch * (i / (side * side)) + 0.6});
    b.radius.push_back(r);
    b.velocity.push_back({u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5});
    if (ellipsoids) {
      const bool ell = i % 3 != 0;
      b.shape.push_back(ell ? Shape::ellipsoid : Shape::sphere);
      b.semi_axes.push_back(ell ? Vec3<double>{r, 0.6 * r, 0.35 * r} : Vec3<double>{r, r, r});
      const double cw = std::cos(0.3 * i), sw = std::sin(0.3 * i);
      b.orientation.push_back(ell ? Quat<double>{cw, sw * 0.6, 0, sw * 0.8} : Quat<double>{1, 0, 0, 0});
    }
  }
  Material m;
  m.young = 1e7;
  m.restitution = 0.6;
  m.friction = 0.4;
  m.rolling_friction = 0.02;
  DemOptions& o = c.options;
  o.material = m;
  o.dt = time_step_limits(b, m, 5.0).automatic;
  o.gravity = {0, 0, -9.81};
  o.walls = {plane({0, 0, 0}, {0, 0, 1}), plane({0, 0, 0}, {1, 0, 0}), plane({9, 0, 0}, {-1, 0, 0}),
             plane({0, 0, 0}, {0, 1, 0}), plane({0, 9, 0}, {0, -1, 0})};
  o.engine.skin = 0.05;
  return c;
}

// rolling: the scene's rolling friction, else none (the CUDA contact stage then stores no torques:
// the body stage takes them from the rows' points, core/dem_step.hpp: torques_from_points).
template <class Real>
void cpu_equals_cuda(bool ellipsoids, bool rolling = true) {
  ComparedScene scene = compared_scene(ellipsoids);
  if (!rolling) scene.options.material.rolling_friction = 0;
  const DemBodies& b = scene.bodies;
  DemOptions oc = scene.options, og = scene.options;
  oc.engine.backend = Backend::cpu;
  og.engine.backend = Backend::cuda;
  Simulation<Real> cpu(b, oc), gpu(b, og);
  for (int block = 0; block < 6; ++block) {
    cpu.run(50);
    gpu.run(50);
    const std::string at =
        std::string(ellipsoids ? "ellipsoids" : "spheres") + " step " + std::to_string(cpu.steps());
    const DemBodies x = cpu.bodies(), y = gpu.bodies();
    ASSERT_EQ(std::memcmp(x.position.data(), y.position.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
    ASSERT_EQ(std::memcmp(x.velocity.data(), y.velocity.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
    ASSERT_EQ(
        std::memcmp(x.angular_velocity.data(), y.angular_velocity.data(), x.size() * sizeof(Vec3<double>)), 0)
        << at;
    if (ellipsoids) {
      ASSERT_EQ(std::memcmp(x.orientation.data(), y.orientation.data(), x.size() * sizeof(Quat<double>)), 0)
          << at;
    }
    ASSERT_EQ(compare_contacts(gpu.contacts(), cpu.contacts()), "identical") << at;
    const DemEnergies ec = cpu.energies(), eg = gpu.energies();
    EXPECT_EQ(ec.kinetic, eg.kinetic) << at;
    EXPECT_EQ(ec.elastic, eg.elastic) << at;
    EXPECT_EQ(ec.gravity, eg.gravity) << at;
  }
}

// The compared scene keeps contacts in every block of the comparison (else a CPU = CUDA comparison of
// it would show little): run on the CPU here, so that the premise holds without a GPU.
template <class Real>
void compared_scene_touches(bool ellipsoids) {
  const ComparedScene scene = compared_scene(ellipsoids);
  DemOptions o = scene.options;
  o.engine.backend = Backend::cpu;
  Simulation<Real> cpu(scene.bodies, o);
  for (int block = 0; block < 6; ++block) {
    cpu.run(50);
    EXPECT_GT(cpu.contact_count(), ellipsoids ? 50u : 100u)
        << (ellipsoids ? "ellipsoids" : "spheres") << " step " << cpu.steps();
  }
}

TEST(DemBackends, TheComparedSceneKeepsItsContacts) {
  compared_scene_touches<double>(false);
  compared_scene_touches<float>(true);
}

TEST(DemBackends, CpuEqualsCudaBitForBit) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  cpu_equals_cuda<double>(false);
  cpu_equals_cuda<float>(false);
  cpu_equals_cuda<double>(true);
  cpu_equals_cuda<float>(true);
}

// The body stage's two indexes on the device (CONTACTGRID_DEM_SUMS=sort: a radix sort and
// lower_bound; default: counts, scans and a segmented sort), and the contact stage's two ways
// (default: every term stored; CONTACTGRID_DEM_TERMS=sums: the sums over the rows as A in the contact
// stage) give the same trajectory, bit for bit.
template <class Real>
void cuda_knob_changes_nothing(bool ellipsoids, const char* variable, const char* value,
                               bool rolling = true) {
  const ComparedScene scene = compared_scene(ellipsoids);
  DemOptions o = scene.options;
  if (!rolling) o.material.rolling_friction = 0;
  o.engine.backend = Backend::cuda;
  Simulation<Real> plain(scene.bodies, o);
  setenv(variable, value, 1);
  Simulation<Real> knob(scene.bodies, o);  // (the knob is read when a simulation starts)
  unsetenv(variable);
  for (int block = 0; block < 3; ++block) {
    plain.run(50);
    knob.run(50);
    const std::string at =
        std::string(ellipsoids ? "ellipsoids" : "spheres") + " step " + std::to_string(plain.steps());
    const DemBodies x = plain.bodies(), y = knob.bodies();
    ASSERT_EQ(std::memcmp(x.position.data(), y.position.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
    ASSERT_EQ(
        std::memcmp(x.angular_velocity.data(), y.angular_velocity.data(), x.size() * sizeof(Vec3<double>)), 0)
        << at;
    ASSERT_GT(plain.contact_count(), 0u) << at;
    const DemEnergies ec = plain.energies(), es = knob.energies();
    EXPECT_EQ(ec.elastic, es.elastic) << at;
  }
}

TEST(DemBackends, CudaSumsBySortEqualCounts) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  cuda_knob_changes_nothing<float>(false, "CONTACTGRID_DEM_SUMS", "sort");
  cuda_knob_changes_nothing<double>(true, "CONTACTGRID_DEM_SUMS", "sort");
}

TEST(DemBackends, CudaTermsByRowsEqualASums) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  cuda_knob_changes_nothing<float>(false, "CONTACTGRID_DEM_TERMS", "sums");
  cuda_knob_changes_nothing<double>(true, "CONTACTGRID_DEM_TERMS", "sums");
}

// Each body's rows as B sorted by its own device thread (default) or by CUB's segmented sort
// (CONTACTGRID_DEM_SEGMENTS=cub): the same order, the same trajectory.
TEST(DemBackends, CudaSegmentsByThreadEqualCub) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  cuda_knob_changes_nothing<float>(false, "CONTACTGRID_DEM_SEGMENTS", "cub");
  cuda_knob_changes_nothing<double>(true, "CONTACTGRID_DEM_SEGMENTS", "cub");
}

// The CUDA contact stage stores only what a later stage reads (no torques without rolling
// resistance: the body stage takes them from the rows' points; fp32 normals as detected; energies on
// a run's last step): the same trajectory and energies as every term stored (CONTACTGRID_DEM_STORE=all)
// and as the CPU's, spheres and ellipsoids, both precisions, with and without rolling resistance.
TEST(DemBackends, CudaStoredTermsOnlyEqualAllAndCpu) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  for (const bool rolling : {false, true}) {
    cuda_knob_changes_nothing<float>(false, "CONTACTGRID_DEM_STORE", "all", rolling);
    cuda_knob_changes_nothing<double>(false, "CONTACTGRID_DEM_STORE", "all", rolling);
    cuda_knob_changes_nothing<float>(true, "CONTACTGRID_DEM_STORE", "all", rolling);
  }
  cpu_equals_cuda<float>(false, false);
  cpu_equals_cuda<double>(false, false);
  cpu_equals_cuda<float>(true, false);
  cpu_equals_cuda<double>(true, false);
}

// sort_rows (the device's per-body sort of its rows as B): ascending, the same as std::sort, at
// every length around its switch from insertion to heapsort and far beyond, from random orders,
// reversed and already sorted.
TEST(DemSum, SortRowsSortsEveryLength) {
  std::mt19937_64 rng(31);
  for (std::size_t m = 0; m <= 70; ++m)
    for (const std::size_t big : {std::size_t(0), std::size_t(1000), std::size_t(4097)}) {
      const std::size_t len = big ? big + m : m;
      std::vector<std::uint32_t> v(len);
      for (std::size_t j = 0; j < len; ++j) v[j] = std::uint32_t(rng() % 100000);
      for (int order = 0; order < 3; ++order) {
        std::vector<std::uint32_t> w = v, want = v;
        std::sort(want.begin(), want.end());
        if (order == 1) w = want;
        if (order == 2) w.assign(want.rbegin(), want.rend());
        dem::sort_rows(w.data(), w.size());
        ASSERT_EQ(w, want) << "length " << len << " order " << order;
      }
    }
}

// Without rolling resistance a body's sums with the torques taken from the rows' points
// (contact_sums_from_points, then body_terms_after_contacts: the CUDA default) are the bits of the
// sums of the torques stored (body_terms: the CPU backend), on random rows of random bodies; with
// rolling resistance the stored torques differ (so the comparison sees the torques at all). And the
// last step's normals read as detected (fp32) give the terms of their doubles.
TEST(DemSum, TermsStoredOnlyWhereReadAreTheSameBits) {
  std::mt19937_64 rng(32);
  std::uniform_real_distribution<double> u(-1, 1);
  const std::size_t n = 300, k = 2000;
  std::vector<Vec3<double>> position(n), velocity(n), omega(n), momentum(n, {0, 0, 0}), force(n), torque(n);
  std::vector<Quat<double>> orientation(n, {1, 0, 0, 0});
  std::vector<dem::BodyProps> props(n);
  std::vector<double> radius(n);
  for (std::size_t i = 0; i < n; ++i) {
    position[i] = {10 * u(rng), 10 * u(rng), 10 * u(rng)};
    velocity[i] = {u(rng), u(rng), u(rng)};
    omega[i] = {3 * u(rng), 3 * u(rng), 3 * u(rng)};
    force[i] = {u(rng), u(rng), u(rng)};
    torque[i] = {0.1 * u(rng), 0.1 * u(rng), 0.1 * u(rng)};
    radius[i] = 0.5 + 0.1 * u(rng);
    props[i] = dem::body_props(Shape::sphere, radius[i], {0, 0, 0}, 2500);
  }
  std::vector<std::int64_t> id_a(k), id_b(k), prev(k, -1);
  std::vector<Vec3<float>> pa(k), pb(k), nb(k);
  std::vector<float> dist(k);
  for (std::size_t r = 0; r < k; ++r) id_a[r] = std::int64_t(rng() % n);
  std::sort(id_a.begin(), id_a.end());  // rows sorted by A, as the engine gives them
  for (std::size_t r = 0; r < k; ++r)
    id_b[r] = (id_a[r] + 1 + std::int64_t(rng() % (n - 1))) % std::int64_t(n);
  for (std::size_t r = 0; r < k; ++r) {
    const Vec3<double> x = position[std::size_t(id_a[r])];
    pa[r] = {float(x.x + 0.3 * u(rng)), float(x.y + 0.3 * u(rng)), float(x.z + 0.3 * u(rng))};
    pb[r] = {float(x.x + 0.3 * u(rng)), float(x.y + 0.3 * u(rng)), float(x.z + 0.3 * u(rng))};
    const Vec3<double> d{u(rng), u(rng), u(rng)};
    const Vec3<double> nd = dem::unit(d);
    nb[r] = {float(nd.x), float(nd.y), float(nd.z)};
    dist[r] = float(-0.01 * (u(rng) + 1.1));
  }
  const dem::ContactRows<float> rows{id_a.data(), id_b.data(), pa.data(),   pb.data(),
                                     nb.data(),   dist.data(), prev.data(), k};
  // the index as the CPU backend makes it: begins of A, rows by B stably
  std::vector<std::uint32_t> a_begin(n + 1, 0), b_begin(n + 1, 0), by_b(k);
  for (std::size_t r = 0; r < k; ++r) {
    ++a_begin[std::size_t(id_a[r]) + 1];
    ++b_begin[std::size_t(id_b[r]) + 1];
  }
  for (std::size_t i = 0; i < n; ++i) {
    a_begin[i + 1] += a_begin[i];
    b_begin[i + 1] += b_begin[i];
  }
  std::vector<std::uint32_t> at(b_begin.begin(), b_begin.end() - 1);
  for (std::size_t r = 0; r < k; ++r) by_b[at[std::size_t(id_b[r])]++] = std::uint32_t(r);
  const dem::BodyRowIndex index{a_begin.data(), b_begin.data(), by_b.data()};
  for (const double rolling : {0.0, 0.05}) {
    dem::StepConstants c{};
    c.law = {1e7, 4e6, 0.3, 0.5, rolling};
    c.gravity = {0, 0, -9.81};
    c.dt = 1e-5;
    c.synchronized = true;
    ASSERT_EQ(dem::torques_from_points(c), rolling == 0);
    std::vector<Vec3<double>> t_force(k), t_ta(k), t_tb(k), xi(k), normal(k);
    std::vector<double> energy(k);
    std::vector<Vec3<double>> f_stored(n), tau_stored(n), f_points(n), tau_points(n), wall_xi(1);
    std::vector<double> wall_energy(n);
    dem::BodyArrays b{
        position.data(), velocity.data(), omega.data(), momentum.data(), orientation.data(), force.data(),
        torque.data(),   props.data(),    nullptr,      nullptr,         radius.data(),      n};
    const dem::ContactTerms t{t_force.data(), t_ta.data(),   t_tb.data(), energy.data(),
                              xi.data(),      normal.data(), nullptr,     nullptr};
    for (std::size_t r = 0; r < k; ++r) dem::contact_terms(r, rows, b, c, t);
    const dem::WallTerms w{wall_xi.data(), wall_energy.data()};
    std::size_t differ = 0;
    for (std::size_t i = 0; i < n; ++i) {
      b.force = f_stored.data();
      b.torque = tau_stored.data();
      dem::body_terms(i, b, c, t, index, w);
      b.force = f_points.data();
      b.torque = tau_points.data();
      Vec3<double> f{0, 0, 0}, tau{0, 0, 0};
      dem::contact_sums_from_points(i, b, rows, t, index, f, tau);
      dem::body_terms_after_contacts(i, b, c, w, f, tau);
      ASSERT_EQ(std::memcmp(&f_stored[i], &f_points[i], sizeof(Vec3<double>)), 0) << "body " << i;
      if (std::memcmp(&tau_stored[i], &tau_points[i], sizeof(Vec3<double>)) != 0) ++differ;
    }
    if (rolling == 0)
      EXPECT_EQ(differ, 0u);
    else
      EXPECT_GT(differ, n / 2);  // the rolling torques, which the points do not give
  }
  // the last step's normals kept as detected (fp32, the CUDA default) or as doubles (ContactTerms):
  // the same terms, bit for bit, for rows with a last step (springs and normals read through it)
  std::vector<std::int64_t> with_prev(k);
  std::vector<Vec3<double>> old_xi(k), old_normal(k);
  std::vector<Vec3<float>> old_normal_f(k);
  for (std::size_t r = 0; r < k; ++r) {
    with_prev[r] = r % 3 == 0 ? -1 : std::int64_t(rng() % k);
    old_xi[r] = {1e-4 * u(rng), 1e-4 * u(rng), 1e-4 * u(rng)};
    old_normal_f[r] = nb[std::size_t(rng() % k)];  // (unit, in float)
  }
  // (apart from the loop above: GCC 12's SLP vectoriser at -O2 drops the rounding of a double to
  // float and back when both conversions meet in one loop body)
  for (std::size_t r = 0; r < k; ++r) old_normal[r] = vec_cast<double>(old_normal_f[r]);
  dem::ContactRows<float> later = rows;
  later.previous_row = with_prev.data();
  dem::StepConstants c{};
  c.law = {1e7, 4e6, 0.3, 0.5, 0.05};
  c.dt = 1e-5;
  c.synchronized = true;
  const dem::BodyArrays b{
      position.data(), velocity.data(), omega.data(), momentum.data(), orientation.data(), force.data(),
      torque.data(),   props.data(),    nullptr,      nullptr,         radius.data(),      n};
  for (std::size_t r = 0; r < k; ++r) {
    const dem::ContactResult x = dem::contact_result(r, later, b, c, old_xi.data(), old_normal.data());
    const dem::ContactResult y = dem::contact_result(r, later, b, c, old_xi.data(), old_normal_f.data());
    ASSERT_EQ(std::memcmp(&x, &y, sizeof(x)), 0) << "row " << r;
  }
}

// The energies' fixed order (core/dem_sum.hpp): chunks of kEnergyChunk summed in item order, then
// the chunks' sums the same way, level by level; the order in which a level's chunks run changes
// nothing. Values of mixed magnitudes and signs, so that another order would give other bits.
TEST(DemSum, TreeSumIsChunksThenTheirChunks) {
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(-1, 1);
  const std::size_t c = dem::kEnergyChunk;
  for (const std::size_t n : {std::size_t(0), std::size_t(1), c - 1, c, c + 1, c * c, c * c * 2 + 5}) {
    std::vector<double> v(n);
    for (std::size_t i = 0; i < n; ++i) v[i] = u(rng) * std::pow(10.0, double(int(i % 13) - 6));
    // by hand: each level's chunks, from the first item to the last
    std::vector<double> level = v;
    do {
      std::vector<double> next((level.size() + c - 1) / c, 0.0);
      for (std::size_t i = 0; i < level.size(); ++i) next[i / c] = next[i / c] + level[i];
      level.swap(next);
    } while (level.size() > 1);
    const double expected = n == 0 ? 0.0 : level[0];
    const auto value = [&](std::size_t i) { return v[i]; };
    const double serial = dem::tree_sum(n, value);
    const double backwards = dem::tree_sum(n, value, [](std::size_t chunks, auto&& f) {
      for (std::size_t k = chunks; k-- > 0;) f(k);
    });
    EXPECT_EQ(std::memcmp(&serial, &expected, sizeof(double)), 0) << n << " items";
    EXPECT_EQ(std::memcmp(&backwards, &expected, sizeof(double)), 0) << n << " items";
    if (n > c * c) {  // the plain sum in item order differs: the test can tell the orders apart
      double plain = 0;
      for (double x : v) plain = plain + x;
      EXPECT_NE(plain, expected) << n << " items";
    }
  }
}

// More bodies and contacts than kEnergyChunk² (the energies' tree three levels deep on both backends),
// steps in runs of several lengths (CUDA: the body stage does the next step's kick_drift within a run,
// a separate pass at a run's start): CPU = CUDA bit for bit, energies too.
TEST(DemBackends, ManyBodiesInRunsCpuEqualsCuda) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0, 1);
  DemBodies b;
  const int side = 40;
  for (int i = 0; i < side * side * 2; ++i) {
    b.position.push_back(
        {0.95 * (i % side) + 0.6, 0.95 * ((i / side) % side) + 0.6, 0.95 * (i / (side * side)) + 0.5});
    b.radius.push_back(0.48 + 0.02 * u(rng));
    b.velocity.push_back({0.2 * (u(rng) - 0.5), 0.2 * (u(rng) - 0.5), 0.2 * (u(rng) - 0.5)});
  }
  Material m;
  m.young = 1e7;
  m.restitution = 0.6;
  m.friction = 0.4;
  DemOptions o;
  o.material = m;
  o.dt = time_step_limits(b, m, 5.0).automatic;
  o.gravity = {0, 0, -9.81};
  o.walls = {plane({0, 0, 0}, {0, 0, 1})};
  o.engine.skin = 0.05;
  o.engine.backend = Backend::cpu;
  Simulation<float> cpu(b, o);
  const std::size_t c = dem::kEnergyChunk;
  cpu.run(1);
  ASSERT_GT(b.size(), c * c);
  ASSERT_GT(cpu.contact_count(), c * c);  // the premise: three levels for the contacts too
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  o.engine.backend = Backend::cuda;
  Simulation<float> gpu(b, o);
  gpu.run(1);
  for (const int steps : {3, 1, 2, 5}) {
    cpu.run(std::uint64_t(steps));
    gpu.run(std::uint64_t(steps));
    const std::string at = "step " + std::to_string(cpu.steps());
    const DemBodies x = cpu.bodies(), y = gpu.bodies();
    ASSERT_EQ(std::memcmp(x.position.data(), y.position.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
    ASSERT_EQ(std::memcmp(x.velocity.data(), y.velocity.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
    ASSERT_EQ(
        std::memcmp(x.angular_velocity.data(), y.angular_velocity.data(), x.size() * sizeof(Vec3<double>)), 0)
        << at;
    const DemEnergies ec = cpu.energies(), eg = gpu.energies();
    EXPECT_EQ(ec.kinetic, eg.kinetic) << at;
    EXPECT_EQ(ec.elastic, eg.elastic) << at;
    EXPECT_EQ(ec.gravity, eg.gravity) << at;
    EXPECT_GT(ec.elastic, 0) << at;
  }
}

// --stage-times: every step's stages are timed in order, the engine's stages within detect too, and
// timing changes nothing of the trajectory.
TYPED_TEST(DemPhysics, StageTimesCoverEveryStepAndChangeNothing) {
  const ComparedScene scene = compared_scene(false);
  DemOptions o = scene.options;
  o.engine.backend = TypeParam::backend;
  Simulation<double> plain(scene.bodies, o);
  o.stage_times = true;
  Simulation<double> timed(scene.bodies, o);
  EXPECT_EQ(plain.stage_times().steps, 0u);
  plain.run(30);
  timed.run(20);
  timed.run(10);
  (void)timed.energies();
  const DemStageTimes t = timed.stage_times();
  EXPECT_EQ(t.steps, 30u);
  const std::vector<std::string> names{"kick_drift", "detect",     "contact_terms",
                                       "body_index", "body_terms", "kick"};
  ASSERT_EQ(t.step.size(), names.size());
  double total = 0;
  for (std::size_t i = 0; i < names.size(); ++i) {
    EXPECT_EQ(t.step[i].name, names[i]);
    EXPECT_GE(t.step[i].seconds, 0) << names[i];
    total += t.step[i].seconds;
  }
  EXPECT_GT(total, 0);
  EXPECT_GT(t.step[1].seconds, 0);  // detect
  EXPECT_FALSE(t.detection.empty());
  EXPECT_EQ(t.energy_calls, 1u);
  const DemBodies x = plain.bodies(), y = timed.bodies();
  EXPECT_EQ(std::memcmp(x.position.data(), y.position.data(), x.size() * sizeof(Vec3<double>)), 0);
  EXPECT_EQ(std::memcmp(x.velocity.data(), y.velocity.data(), x.size() * sizeof(Vec3<double>)), 0);
}

}  // namespace
}  // namespace cg::test
