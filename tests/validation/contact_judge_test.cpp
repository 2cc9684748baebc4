// Tests of the validation judge (src/validate/contact_judge.hpp) on pairs whose contact is known by
// construction, never from the engine: B is placed so that a chosen point of A's surface and its
// normal coincide with B's support point along n, so the pair touches exactly (distance 0) with that
// n the global minimiser; then each condition is broken one at a time. Crossed bodies (a needle through
// a plate) give f a local minimum that is not the global one, which the judge must reject.
#include "validate/contact_judge.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace cg::judge {
namespace {

Vec3<double> narrow(V v) { return {double(v.x), double(v.y), double(v.z)}; }
V unit_of(V v) { return (1 / std::sqrt(dot(v, v))) * v; }

// A random unit quaternion (w, x, y, z).
std::array<double, 4> random_rotation(std::mt19937_64& rng) {
  std::normal_distribution<double> g;
  std::array<double, 4> q{g(rng), g(rng), g(rng), g(rng)};
  const double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (double& c : q) c /= len;
  return q;
}

struct Touching {
  Body a, b;
  Answer right;  // the exact contact, distance 0
};

// A with centre `centre_a`; B placed so that the support points of A along −n and of B along n
// coincide (distance 0, n global: for convex bodies that touch, the common normal is the minimiser).
Touching touching_pair(Vec3<double> centre_a, Vec3<double> semi_a, std::array<double, 4> qa,
                       Vec3<double> semi_b, std::array<double, 4> qb, V n) {
  const Body a = ellipsoid(centre_a, semi_a, qa);
  const V point = a.centre + a.support_offset(-n);
  const Body b_at_origin = ellipsoid({0, 0, 0}, semi_b, qb);
  const Vec3<double> centre_b = narrow(point - b_at_origin.support_offset(n));
  const Body b = ellipsoid(centre_b, semi_b, qb);
  const V pb = b.centre + b.support_offset(n);
  return {a, b, {narrow(point), narrow(pb), narrow(n), 0.0}};
}

Vec3<double> rotate_about(Vec3<double> v, Vec3<double> axis, double deg) {
  const double t = deg * 3.141592653589793 / 180, c = std::cos(t), s = std::sin(t);
  const double k = dot(axis, v);
  const Vec3<double> kxv = cross(axis, v);
  return Vec3<double>{c * v.x + s * kxv.x + (1 - c) * k * axis.x, c * v.y + s * kxv.y + (1 - c) * k * axis.y,
                      c * v.z + s * kxv.z + (1 - c) * k * axis.z};
}

TEST(ContactJudge, AcceptsExactTouchingPairsRejectsEachBrokenCondition) {
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> semi(0.3, 1.5), coord(-50, 50);
  std::normal_distribution<double> g;
  const double tol = 1e-6;
  for (int trial = 0; trial < 40; ++trial) {
    const Vec3<double> ca{coord(rng), coord(rng), coord(rng)};
    const V n = unit_of(V{g(rng), g(rng), g(rng)});
    const Touching t = touching_pair(ca, {semi(rng), semi(rng), semi(rng)}, random_rotation(rng),
                                     {semi(rng), semi(rng), semi(rng)}, random_rotation(rng), n);
    const Verdict ok = judge_answer(t.a, t.b, t.right, tol);
    ASSERT_TRUE(ok.ok) << "trial " << trial << ": " << ok.reason;
    EXPECT_NEAR(ok.distance, 0.0, 1e-9);

    // The normal turned by 30° about a perpendicular axis: the surface normals no longer match.
    Answer turned = t.right;
    const Vec3<double> axis = narrow(unit_of(cross(n, V{g(rng), g(rng), g(rng)})));
    turned.normal_on_b = rotate_about(t.right.normal_on_b, axis, 30);
    const Verdict v1 = judge_answer(t.a, t.b, turned, tol);
    EXPECT_FALSE(v1.ok);
    EXPECT_NE(v1.reason.find("surface normal"), std::string::npos) << v1.reason;

    // The distance changed: the points no longer differ by n·distance.
    Answer deeper = t.right;
    deeper.distance = -0.05;
    const Verdict v2 = judge_answer(t.a, t.b, deeper, tol);
    EXPECT_FALSE(v2.ok);
    EXPECT_NE(v2.reason.find("n·distance"), std::string::npos) << v2.reason;

    // A point moved off its surface along the normal.
    Answer lifted = t.right;
    lifted.position_on_b = lifted.position_on_b + 0.01 * lifted.normal_on_b;
    const Verdict v3 = judge_answer(t.a, t.b, lifted, tol);
    EXPECT_FALSE(v3.ok);
    EXPECT_NE(v3.reason.find("off B's surface"), std::string::npos) << v3.reason;

    // Not a unit normal.
    Answer longer = t.right;
    longer.normal_on_b = 1.01 * longer.normal_on_b;
    EXPECT_FALSE(judge_answer(t.a, t.b, longer, tol).ok);
  }
}

TEST(ContactJudge, SpheresFollowTheClosedForm) {
  // Sphere (radius 1) at the origin and ellipsoid (0.5, 0.5, 0.5) — a sphere too — 1.2 apart on x.
  const Body a = sphere({1.2, 0, 0}, 1.0);
  const Body b = ellipsoid({0, 0, 0}, {0.5, 0.5, 0.5}, {1, 0, 0, 0});
  const Answer right{{0.2, 0, 0}, {0.5, 0, 0}, {1, 0, 0}, -0.3};
  const Verdict v = judge_answer(a, b, right, 1e-9);
  EXPECT_TRUE(v.ok) << v.reason;
  EXPECT_NEAR(v.distance, -0.3, 1e-12);
  const Answer flipped{{0.5, 0, 0}, {0.2, 0, 0}, {-1, 0, 0}, 0.3};
  EXPECT_FALSE(judge_answer(a, b, flipped, 1e-9).ok);
}

// Crossed bodies: a needle (0.3, 0.3, 5) along z through a plate (5, 4, 0.3) in the xy plane, same
// centre (every axis direction is then a critical point of f by symmetry). f(n) = h_A(−n) + h_B(n)
// has its global minimum at n = ±y (slide the needle off the plate's narrower width: depth 4 + 0.3 =
// 4.3) and local minima at n = ±z (pull the needle out along its length: depth 0.3 + 5 = 5.3): from
// ±z, tilting towards x or y grows the plate's support (curvature 25/0.3, 16/0.3) faster than it
// shrinks the needle's (24.9/5). The answer built at −z satisfies every local condition and must be
// rejected as not global; the one at y passes.
TEST(ContactJudge, CrossedBodiesLocalMinimumRejected) {
  const std::array<double, 4> identity{1, 0, 0, 0};
  const Body a = ellipsoid({0, 0, 0}, {5, 4, 0.3}, identity);    // the plate
  const Body b = ellipsoid({0, 0, 0}, {0.3, 0.3, 5}, identity);  // the needle

  auto answer_at = [&](V n) {
    const V pa = a.centre + a.support_offset(-n), pb = b.centre + b.support_offset(n);
    return Answer{narrow(pa), narrow(pb), narrow(n), double(-contact_function(a, b, n))};
  };
  const V y{0, 1, 0}, down{0, 0, -1};
  // −z is a local minimum: f grows on a small cap around it, and lies 1 above the global one.
  const LD f_local = contact_function(a, b, down);
  EXPECT_NEAR(double(f_local), 5.3, 1e-12);
  for (const V d : {V{1, 0, 0}, V{-1, 0, 0}, V{0, 1, 0}, V{0, -1, 0}, unit_of(V{1, 1, 0})})
    EXPECT_GT(contact_function(a, b, unit_of(down + LD(0.02) * d)), f_local);
  EXPECT_NEAR(double(contact_function(a, b, y)), 4.3, 1e-12);

  const Verdict global = judge_answer(a, b, answer_at(y), 1e-6);
  EXPECT_TRUE(global.ok) << global.reason;
  EXPECT_NEAR(global.distance, -4.3, 1e-9);

  const Verdict local = judge_answer(a, b, answer_at(down), 1e-6);
  EXPECT_FALSE(local.ok);
  EXPECT_NE(local.reason.find("not the global minimum"), std::string::npos) << local.reason;
  EXPECT_NEAR(local.distance, -4.3, 1e-9);
}

}  // namespace
}  // namespace cg::judge
