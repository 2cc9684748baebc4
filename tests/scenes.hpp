#pragma once
// Adversarial and random test scenes for the engine, deterministic from a seed. Each returns spheres
// as (positions, radii) in double. Fresh seeds per test case; never only zeros or regular grids.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "bodies.hpp"
#include "core/vec3.hpp"

namespace cg::test {

struct Spheres {
  std::string name;
  std::vector<Vec3<double>> p;
  std::vector<double> r;
  void add(double x, double y, double z, double rad) {
    p.push_back({x, y, z});
    r.push_back(rad);
  }
  Spheres translated(Vec3<double> o) const {
    Spheres s = *this;
    for (auto& q : s.p) q = q + o;
    return s;
  }
};

// Radii uniform in [rl, rh] (or log-uniform when `log_radii`), centres uniform in a cube whose edge
// gives about 0.4 contacts per sphere.
inline Spheres random_spheres(std::size_t n, double rl, double rh, std::uint64_t seed,
                              bool log_radii = false) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  Spheres s;
  s.name = "random n=" + std::to_string(n) + " r=[" + std::to_string(rl) + "," + std::to_string(rh) + "]";
  std::vector<double> rad(n);
  double vol = 0;
  for (auto& x : rad) {
    x = log_radii ? rl * std::pow(rh / rl, u(rng)) : rl + (rh - rl) * u(rng);
    vol += x * x * x;
  }
  // mean contacts ≈ (n/L^3)·(4π/3)·E[(ra+rb)^3]; E[(ra+rb)^3] ≈ 8·mean(r^3) for narrow laws.
  const double mean_r3 = vol / double(n);
  const double L = std::cbrt(double(n) * 4.18879 * 8 * mean_r3 / (2 * 0.4)) + 2 * rh;
  for (std::size_t i = 0; i < n; ++i) s.add(u(rng) * L, u(rng) * L, u(rng) * L, rad[i]);
  return s;
}

// A few dense Gaussian clusters (many spheres per cell, deep overlaps).
inline Spheres clustered(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, 2.0);
  std::uniform_real_distribution<double> u(0, 1);
  Spheres s;
  s.name = "clustered";
  const Vec3<double> c[3] = {{0, 0, 0}, {15, 3, -4}, {5, 20, 9}};
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3<double> o = c[i % 3];
    s.add(o.x + g(rng), o.y + g(rng), o.z + g(rng), 0.3 + 0.4 * u(rng));
  }
  return s;
}

// Every sphere in one cell (cell edge = largest diameter, all centres within a tiny box).
inline Spheres one_cell(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  Spheres s;
  s.name = "one cell";
  for (std::size_t i = 0; i < n; ++i) s.add(0.05 * u(rng), 0.05 * u(rng), 0.05 * u(rng), 0.5 + 0.5 * u(rng));
  return s;
}

// Centres and box faces exactly on cell boundaries (binary-exact coordinates, unit radii, cell 2).
inline Spheres on_boundaries(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  Spheres s;
  s.name = "on cell boundaries";
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j)
      for (int k = 0; k < 6; ++k)
        if ((rng() & 3) != 0) s.add(1.0 * i + 0.5 * (rng() & 1), 1.0 * j, 1.0 * k, 0.5);
  return s;
}

// Pairs with coincident centres (and some nearly coincident).
inline Spheres coincident(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  Spheres s;
  s.name = "coincident centres";
  for (int i = 0; i < 50; ++i) {
    double x = 10 * u(rng), y = 10 * u(rng), z = 10 * u(rng);
    s.add(x, y, z, 0.5);
    s.add(x, y, z, 0.25 + 0.5 * u(rng));
    if (i % 5 == 0) s.add(std::nextafter(x, 100.0), y, z, 0.5);
  }
  return s;
}

// Exactly tangent pairs: integer Pythagorean offsets scaled by powers of two, so d = ra + rb exactly
// in binary and d² = (ra + rb)² exactly too.
inline Spheres tangent(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  Spheres s;
  s.name = "exactly tangent";
  const int trip[][4] = {{3, 4, 0, 5}, {0, 3, 4, 5}, {1, 2, 2, 3}, {2, 3, 6, 7}, {1, 4, 8, 9}, {5, 0, 0, 5}};
  for (int i = 0; i < 200; ++i) {
    const auto& t = trip[rng() % 6];
    const double scale = 1.0 / 8;  // offsets t·scale, sum of radii t[3]·scale
    const double x = double(rng() % 4096) / 16, y = double(rng() % 4096) / 16, z = double(rng() % 4096) / 16;
    const double ra = t[3] * scale * double(1 + rng() % 3) / 4;
    const double rb = t[3] * scale - ra;
    s.add(x, y, z, ra);
    s.add(x + t[0] * scale, y + t[1] * scale, z + t[2] * scale, rb);
  }
  return s;
}

// A scene of spheres and ellipsoids (body i has id i) in [0, L]^3.
struct ShapeScene {
  std::string name;
  double extent = 0;
  std::vector<Vec3<double>> p;
  std::vector<double> r;
  std::vector<Shape> shape;
  std::vector<Vec3<double>> axes;
  std::vector<Quat<double>> q;
  BodiesView view() const {
    BodiesView v{p, r, {}, {}};
    v.shape = shape;
    v.semi_axes = axes;
    v.orientation = q;
    return v;
  }
};

// n bodies, a fraction `ellipsoid_share` ellipsoids (semi-axes in [0.2, 1]: axis ratios up to 5,
// uniformly random orientations), the rest spheres (radius in [0.3, 1]); extent L chosen for a few
// hundred bounding-sphere overlaps.
inline ShapeScene make_scene(const std::string& name, std::uint32_t seed, int n, double ellipsoid_share,
                             double L) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0, 1), axis(0.2, 1.0), rad(0.3, 1.0);
  std::normal_distribution<double> gauss;
  ShapeScene s;
  s.name = name + " seed " + std::to_string(seed);
  s.extent = L;
  for (int i = 0; i < n; ++i) {
    s.p.push_back({L * u01(rng), L * u01(rng), L * u01(rng)});
    if (u01(rng) < ellipsoid_share) {
      const Vec3<double> e{axis(rng), axis(rng), axis(rng)};
      double w = gauss(rng), x = gauss(rng), y = gauss(rng), z = gauss(rng);
      const double k = 1 / std::sqrt(w * w + x * x + y * y + z * z);
      s.shape.push_back(Shape::ellipsoid);
      s.axes.push_back(e);
      s.q.push_back({w * k, x * k, y * k, z * k});
      s.r.push_back(std::max(e.x, std::max(e.y, e.z)));
    } else {
      const double r = rad(rng);
      s.shape.push_back(Shape::sphere);
      s.axes.push_back({0, 0, 0});  // not read for spheres
      s.q.push_back({0, 0, 0, 0});
      s.r.push_back(r);
    }
  }
  return s;
}

}  // namespace cg::test
