// The spin of the resident steps (detect --steps N --spin W, comm/resident_steps.hpp): each body turns
// about its own fixed axis, a pure function of its id, so any rank (and the checks) computes any
// body's orientation at any step from the id alone. References in long double.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/quat.hpp"
#include "resident_steps.hpp"

namespace cg {
namespace {

long double norm(Quat<double> q) {
  return std::sqrt((long double)q.w * q.w + (long double)q.x * q.x + (long double)q.y * q.y +
                   (long double)q.z * q.z);
}

// The rotation that takes q0 to q: q q0* (long double), as (angle, unit axis).
struct Turn {
  long double angle;
  Vec3<long double> axis;
};
Turn turn_between(Quat<double> q0, Quat<double> q) {
  using L = long double;
  const L w = L(q.w) * q0.w + L(q.x) * q0.x + L(q.y) * q0.y + L(q.z) * q0.z;
  const L x = -L(q.w) * q0.x + L(q.x) * q0.w - L(q.y) * q0.z + L(q.z) * q0.y;
  const L y = -L(q.w) * q0.y + L(q.x) * q0.z + L(q.y) * q0.w - L(q.z) * q0.x;
  const L z = -L(q.w) * q0.z - L(q.x) * q0.y + L(q.y) * q0.x + L(q.z) * q0.w;
  const L s = std::sqrt(x * x + y * y + z * z);
  return {2 * std::atan2(s, w), {x / s, y / s, z / s}};
}

Quat<double> random_unit(std::mt19937_64& rng) {
  std::normal_distribution<double> g;
  Quat<double> q{g(rng), g(rng), g(rng), g(rng)};
  const double n = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  return {q.w / n, q.x / n, q.y / n, q.z / n};
}

TEST(SpinRule, EachBodyTurnsByTheAngleAboutItsOwnFixedAxis) {
  std::mt19937_64 rng(2024);
  std::uniform_int_distribution<std::int64_t> ids(0, std::int64_t(1) << 40);
  Vec3<double> mean{0, 0, 0};
  const int n = 2000;
  for (int k = 0; k < n; ++k) {
    const std::int64_t id = k < 5 ? k : ids(rng);  // the first ids too
    const Vec3<double> a = spin_axis(id);
    EXPECT_NEAR(std::sqrt(a.x * a.x + a.y * a.y + a.z * a.z), 1.0, 1e-15) << id;
    mean = {mean.x + a.x / n, mean.y + a.y / n, mean.z + a.z / n};
    const Quat<double> q0 = random_unit(rng);
    EXPECT_EQ(spun_orientation(id, q0, 0).w, q0.w);  // angle 0: the orientation as given
    const double angle = 0.3 * double(1 + k % 5);
    const Quat<double> q = spun_orientation(id, q0, angle);
    EXPECT_NEAR(double(norm(q)), 1.0, 1e-15) << id;  // unit: the engine's check (1e-5) holds at any step
    const Turn t = turn_between(q0, q);
    EXPECT_NEAR(double(t.angle), angle, 1e-13) << id;
    EXPECT_NEAR(double(t.axis.x * a.x + t.axis.y * a.y + t.axis.z * a.z), 1.0, 1e-13) << id;
    // the axis stays put: a turn at step s equals s turns of one step
    Quat<double> stepped = q0;
    for (int s = 0; s < 3; ++s) stepped = spun_orientation(id, stepped, 0.3);
    const Quat<double> direct = spun_orientation(id, q0, 0.9);
    EXPECT_NEAR(stepped.w, direct.w, 1e-14);
    EXPECT_NEAR(stepped.x, direct.x, 1e-14);
    EXPECT_NEAR(stepped.z, direct.z, 1e-14);
  }
  // the axes are spread over the sphere (their mean is near 0: 2000 draws, sd 1/sqrt(3n) ~ 0.013)
  EXPECT_LT(std::sqrt(mean.x * mean.x + mean.y * mean.y + mean.z * mean.z), 0.08);
  // distinct bodies, distinct axes
  const Vec3<double> a0 = spin_axis(0), a1 = spin_axis(1);
  EXPECT_LT(a0.x * a1.x + a0.y * a1.y + a0.z * a1.z, 0.999);
}

}  // namespace
}  // namespace cg
