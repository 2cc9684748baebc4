#pragma once
// The scene generators' randomness: a counter-based generator. Value (seed, body i, stream s) =
// splitmix64 finalizer of (key(seed) XOR splitmix64(16·i + s)); a bijection of the counter for a fixed
// seed, so body i's values depend on nothing but (seed, i). Shared by generate.cpp and the tests'
// scene builders (test_scenes.cpp).
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>

namespace cg::scene_rng {

constexpr std::uint64_t mix64(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

// Streams of one body (at most 16).
enum Stream : unsigned {
  kX = 0,
  kY = 1,
  kZ = 2,
  kRadius = 3,
  kGauss0 = 4,
  kGauss1 = 5,
  kGauss2 = 6,
  kGauss3 = 7,
  kAxisA = 8,
  kAxisB = 9,
  kAxisC = 10,
  kQuat0 = 11,
  kQuat1 = 12,
  kQuat2 = 13,
  kCluster = 14
};

class CounterRng {
 public:
  explicit CounterRng(std::uint64_t seed) : m_key(mix64(seed ^ 0x6a09e667f3bcc909ull)) {}
  // Uniform in [0, 1), 53 bits.
  double unit(std::uint64_t index, unsigned stream) const {
    std::uint64_t bits = mix64(m_key ^ mix64(index * 16 + stream));
    return static_cast<double>(bits >> 11) * 0x1.0p-53;
  }
  // Standard normal (Box–Muller on two streams).
  double normal(std::uint64_t index, unsigned stream_a, unsigned stream_b) const {
    double u1 = 1.0 - unit(index, stream_a);  // (0, 1]
    double u2 = unit(index, stream_b);
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
  }

 private:
  std::uint64_t m_key;
};

// Body i's orientation: a unit quaternion (w, x, y, z), uniform on SO(3) (Shoemake), from three
// uniforms.
inline std::array<double, 4> random_quaternion(const CounterRng& rng, std::uint64_t i) {
  double u1 = rng.unit(i, kQuat0), u2 = rng.unit(i, kQuat1), u3 = rng.unit(i, kQuat2);
  double a = std::sqrt(1 - u1), b = std::sqrt(u1), tau = 2 * std::numbers::pi;
  std::array<double, 4> q{a * std::sin(tau * u2), a * std::cos(tau * u2), b * std::sin(tau * u3),
                          b * std::cos(tau * u3)};
  double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (double& c : q) c /= norm;
  return q;
}

}  // namespace cg::scene_rng
