#pragma once
// Test helpers for the validation suite: seeded random sphere scenes and their exact contacts by a
// brute-force sweep with the docs/FORMAT.md §3 formulas, independent of the engine.
// Invariant: contacts come out sorted by (id_a, id_b), id_a < id_b, each pair once.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <random>
#include <vector>

#include "engine.hpp"
#include "scene/scene.hpp"

namespace cg::testing {

// n spheres, radii uniform in [r_lo, r_hi], centres uniform in a cube of edge `edge` at `offset`.
inline Scene random_scene(std::size_t n, double edge, std::uint64_t seed, Vec3<double> offset = {0, 0, 0},
                          double r_lo = 0.5, double r_hi = 1.0) {
  Scene s;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, edge), r(r_lo, r_hi);
  for (std::size_t i = 0; i < n; ++i) {
    const double x = u(rng), y = u(rng), z = u(rng);
    s.sphere_position.push_back({offset.x + x, offset.y + y, offset.z + z});
    s.sphere_radius.push_back(r(rng));
  }
  return s;
}

// Cube edge giving about `per_body` contacts per body for radii in [0.5, 1] (small-t approximation).
inline double edge_for(std::size_t n, double per_body = 0.4) {
  const double mean_s3 = 3.375 * 1.05;  // E[(r1 + r2)^3] for r ~ U[0.5, 1], about (1.5)^3 · 1.05
  return std::cbrt(double(n - 1) / 2 * 4.0 / 3 * 3.141592653589793 * mean_s3 / per_body);
}

// Appends the contact of spheres a < b per docs/FORMAT.md §3.
inline void push_contact(Contacts<double>& c, const Scene& s, std::int64_t a, std::int64_t b) {
  const Vec3<double> ca = s.sphere_position[std::size_t(a)], cb = s.sphere_position[std::size_t(b)];
  const double ra = s.sphere_radius[std::size_t(a)], rb = s.sphere_radius[std::size_t(b)];
  const Vec3<double> d = ca - cb;
  const double len = std::sqrt(dot(d, d));
  const Vec3<double> n = len > 2.220446049250313e-16 ? (1.0 / len) * d : Vec3<double>{1, 0, 0};
  c.id_a.push_back(a);
  c.id_b.push_back(b);
  c.normal_on_b.push_back(n);
  c.position_on_b.push_back(cb + rb * n);
  c.position_on_a.push_back(ca - ra * n);
  c.distance.push_back(len - (ra + rb));
}

// Exact contacts (d <= ra + rb) by a sweep along x.
inline Contacts<double> brute_force_contacts(const Scene& s) {
  const std::size_t n = s.sphere_count();
  const double r_max = n ? *std::max_element(s.sphere_radius.begin(), s.sphere_radius.end()) : 0;
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t(0));
  std::sort(order.begin(), order.end(),
            [&](std::size_t i, std::size_t j) { return s.sphere_position[i].x < s.sphere_position[j].x; });
  std::vector<std::pair<std::int64_t, std::int64_t>> pairs;
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t i = order[k];
    for (std::size_t m = k + 1; m < n; ++m) {
      const std::size_t j = order[m];
      if (s.sphere_position[j].x - s.sphere_position[i].x > 2 * r_max) break;
      const Vec3<double> d = s.sphere_position[i] - s.sphere_position[j];
      const double rr = s.sphere_radius[i] + s.sphere_radius[j];
      if (dot(d, d) <= rr * rr)
        pairs.emplace_back(std::int64_t(std::min(i, j)), std::int64_t(std::max(i, j)));
    }
  }
  std::sort(pairs.begin(), pairs.end());
  Contacts<double> c;
  for (auto [a, b] : pairs) push_contact(c, s, a, b);
  return c;
}

// Removes row r of every dataset.
inline void erase_row(Contacts<double>& c, std::size_t r) {
  c.id_a.erase(c.id_a.begin() + std::ptrdiff_t(r));
  c.id_b.erase(c.id_b.begin() + std::ptrdiff_t(r));
  c.position_on_a.erase(c.position_on_a.begin() + std::ptrdiff_t(r));
  c.position_on_b.erase(c.position_on_b.begin() + std::ptrdiff_t(r));
  c.normal_on_b.erase(c.normal_on_b.begin() + std::ptrdiff_t(r));
  c.distance.erase(c.distance.begin() + std::ptrdiff_t(r));
}

// Moves the last row to position r (keeps everything else in order).
inline void move_last_to(Contacts<double>& c, std::size_t r) {
  auto rot = [r](auto& v) { std::rotate(v.begin() + std::ptrdiff_t(r), v.end() - 1, v.end()); };
  rot(c.id_a), rot(c.id_b), rot(c.position_on_a), rot(c.position_on_b), rot(c.normal_on_b), rot(c.distance);
}

}  // namespace cg::testing
