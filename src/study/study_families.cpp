// The scene families of `contactgrid study` (study_families.hpp). Generated families reuse
// generate_scene (the same scenes `contactgrid generate` writes); the adversarial ones are built here
// from a seeded std::mt19937_64, pair by pair, with the geometry stated in each builder.
#include "study/study_families.hpp"

#include <algorithm>
#include <cmath>
#include <random>

#include "reference/ellipsoid_reference.hpp"
#include "scene/generate.hpp"

namespace cg {
namespace {

std::uint64_t scaled(double base, double scale) {
  return std::max<std::uint64_t>(2, std::uint64_t(std::llround(base * scale)));
}

void add_sphere(BodyRows& rows, Vec3<double> c, double r) {
  rows.position.push_back(c);
  rows.radius.push_back(r);
}

BodyRows generated(const std::string& kind, std::uint64_t n, std::uint64_t seed, double r_low,
                   Vec3<double> offset = {0, 0, 0}) {
  GenerateOptions g;
  g.kind = kind;
  g.count = n;
  g.seed = seed;
  g.radius_low = r_low;
  g.radius_high = 1;
  g.offset = offset;
  return body_rows(generate_scene(g), false);
}

// Exactly tangent pairs: offsets t·(1/8) with t a Pythagorean quadruple (t0² + t1² + t2² = t3²), radii
// summing to t3/8, so d = ra + rb in binary. Then b moves by `ulps` (−1, 0, +1, drawn per axis) ulps
// of Real on each axis: the exact distance changes by about one ulp, which only an exact reference
// decides. Coordinates are multiples of 1/16 below 256: exact in float and double.
template <class Real>
BodyRows tangent_pairs(std::uint64_t pairs, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const int quad[][4] = {{3, 4, 0, 5}, {0, 3, 4, 5}, {1, 2, 2, 3}, {2, 3, 6, 7}, {1, 4, 8, 9}, {5, 0, 0, 5}};
  auto nudge = [&](double x) {
    const int k = int(rng() % 3) - 1;
    const Real v = Real(x);
    return k == 0 ? x : double(std::nextafter(v, k > 0 ? Real(1e30) : Real(-1e30)));
  };
  BodyRows rows;
  for (std::uint64_t i = 0; i < pairs; ++i) {
    const auto& t = quad[rng() % 6];
    const double x = double(rng() % 4096) / 16, y = double(rng() % 4096) / 16, z = double(rng() % 4096) / 16;
    const double ra = t[3] / 8.0 * double(1 + rng() % 3) / 4, rb = t[3] / 8.0 - ra;
    add_sphere(rows, {x, y, z}, ra);
    add_sphere(rows, {nudge(x + t[0] / 8.0), nudge(y + t[1] / 8.0), nudge(z + t[2] / 8.0)}, rb);
  }
  return rows;
}

// Sphere pairs whose centres are `separation` apart in a random direction (then rounded to double),
// centres uniform in [0, 100)^3: the engine's frame origin (the scene's lower corner) is then far from
// most centres relative to their separation (near 70 a double's ulp is 1.4e-14, so 1e-12 is ~70
// ulps). Then pairs/4 pairs with an ellipsoid (sphere–ellipsoid, ellipsoid–sphere, ellipsoid–ellipsoid
// in turn; semi-axes 1 ≥ e ≥ 0.3, all different, random orientations) 1e-3 … 1e-12 apart: not 0, where
// the mirror normals ±n tie exactly and the contract's canonical one need not be the reference's.
BodyRows near_coincident(std::uint64_t pairs, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> g;
  BodyRows rows;
  auto add = [&](Vec3<double> c, bool ellipsoid) {
    if (!ellipsoid) {
      add_sphere(rows, c, 0.5 + 0.5 * u(rng));
      rows.shape.push_back(Shape::sphere), rows.semi_axes.push_back({0, 0, 0});
      rows.orientation.push_back({1, 0, 0, 0});
      return;
    }
    const Vec3<double> e{1, 0.65 + 0.3 * u(rng), 0.3 + 0.3 * u(rng)};
    const double q[4] = {g(rng), g(rng), g(rng), g(rng)};
    const double k = 1 / std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    add_sphere(rows, c, 1);
    rows.shape.push_back(Shape::ellipsoid), rows.semi_axes.push_back(e);
    rows.orientation.push_back({q[0] * k, q[1] * k, q[2] * k, q[3] * k});
  };
  auto pair = [&](double separation, bool ellipsoid_a, bool ellipsoid_b) {
    const Vec3<double> a{100 * u(rng), 100 * u(rng), 100 * u(rng)};
    Vec3<double> dir{g(rng), g(rng), g(rng)};
    const double s = separation / std::sqrt(dot(dir, dir));
    add(a, ellipsoid_a);
    add({a.x + s * dir.x, a.y + s * dir.y, a.z + s * dir.z}, ellipsoid_b);
  };
  const double separations[] = {0, 1e-3, 1e-6, 1e-9, 1e-12};
  for (std::uint64_t i = 0; i < pairs; ++i) pair(separations[i % 5], false, false);
  for (std::uint64_t i = 0; i < std::max<std::uint64_t>(3, pairs / 4); ++i)
    pair(separations[1 + i % 4], i % 3 != 0, i % 3 != 1);
  return rows;
}

// 32 centres per cell of edge 2 (= the largest diameter): n centres uniform in a cube of edge
// 2·cbrt(n/32), radii uniform in [0.5, 1] (~57 contacts per body).
BodyRows dense(std::uint64_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  const double edge = 2 * std::cbrt(double(n) / 32);
  BodyRows rows;
  for (std::uint64_t i = 0; i < n; ++i)
    add_sphere(rows, {edge * u(rng), edge * u(rng), edge * u(rng)}, 0.5 + 0.5 * u(rng));
  return rows;
}

// Pairs of ellipsoids of aspect k (largest / smallest semi-axis; the largest is 1), random
// orientations, placed so that they touch at one point: for a random unit n (B → A), A's support point
// along −n and B's along n coincide (b = a + s_A(−n) − s_B(n), the support points of the exact
// reference in long double), then B moves by −gap·n: apart for gap > 0, overlapping for gap < 0, the
// exact distance ≈ gap. Pairs sit on a lattice of spacing 8 (bounding radius 1), so pairs never meet.
BodyRows ellipsoid_pairs(std::uint64_t repeats, std::uint64_t seed) {
  using exact::LD;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> g;
  const double aspects[] = {1, 2, 5, 10};
  const double gaps[] = {-1e-2, -1e-5, -1e-8, 0, 1e-8, 1e-5, 1e-2};
  auto random_unit4 = [&] {
    std::array<double, 4> q{g(rng), g(rng), g(rng), g(rng)};
    const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (double& c : q) c /= n;
    return q;
  };
  auto random_axes = [&](double k) {  // largest exactly 1 (the bounding radius), smallest 1/k
    std::array<double, 3> e{1, 1 / k + (1 - 1 / k) * u(rng), 1 / k};
    std::shuffle(e.begin(), e.end(), rng);
    return Vec3<double>{e[0], e[1], e[2]};
  };
  BodyRows rows;
  auto add = [&](Vec3<double> c, Vec3<double> e, std::array<double, 4> q) {
    rows.position.push_back(c);
    rows.radius.push_back(std::max({e.x, e.y, e.z}));
    rows.shape.push_back(Shape::ellipsoid);
    rows.semi_axes.push_back(e);
    rows.orientation.push_back({q[0], q[1], q[2], q[3]});
  };
  std::uint64_t cell = 0;
  for (double k : aspects)
    for (double gap : gaps)
      for (std::uint64_t rep = 0; rep < repeats; ++rep, ++cell) {
        const Vec3<double> a{8.0 * double(cell % 16), 8.0 * double(cell / 16 % 16), 8.0 * double(cell / 256)};
        const Vec3<double> ea = random_axes(k), eb = random_axes(k);
        const auto qa = random_unit4(), qb = random_unit4();
        const exact::V n = exact::unit({LD(g(rng)), LD(g(rng)), LD(g(rng))});
        const exact::Body A =
            exact::make_body({a.x, a.y, a.z}, {ea.x, ea.y, ea.z}, {qa[0], qa[1], qa[2], qa[3]});
        const exact::Body B = exact::make_body({0, 0, 0}, {eb.x, eb.y, eb.z}, {qb[0], qb[1], qb[2], qb[3]});
        const exact::V b = exact::sub(exact::add(A.centre, exact::support_point(A, exact::scale(-1, n))),
                                      exact::add(exact::support_point(B, n), exact::scale(LD(gap), n)));
        add(a, ea, qa);
        add({double(b.x), double(b.y), double(b.z)}, eb, qb);
      }
  return rows;
}

}  // namespace

BodiesView bodies_view(const BodyRows& rows) {
  return BodiesView{rows.position, rows.radius, {}, {}, rows.shape, rows.semi_axes, rows.orientation};
}

const std::vector<StudyFamily>& study_families() {
  static const std::vector<StudyFamily> families{
      {"uniform", false,
       [](double s, std::uint64_t seed) { return generated("uniform", scaled(1 << 18, s), seed, 0.5); }},
      {"polydisperse-1:1000", false,
       [](double s, std::uint64_t seed) {
         return generated("polydisperse", scaled(1 << 18, s), seed, 1e-3);
       }},
      {"far-1e6", false,
       [](double s, std::uint64_t seed) {
         return generated("uniform", scaled(1 << 16, s), seed, 0.5, {1e6, -1e6, 1e6});
       }},
      {"far-1e8", false,
       [](double s, std::uint64_t seed) {
         return generated("uniform", scaled(1 << 16, s), seed, 0.5, {1e8, -1e8, 1e8});
       }},
      {"tangent-ulp-double", false,
       [](double s, std::uint64_t seed) { return tangent_pairs<double>(scaled(16000, s), seed); }},
      {"tangent-ulp-float", false,
       [](double s, std::uint64_t seed) { return tangent_pairs<float>(scaled(16000, s), seed); }},
      {"near-coincident", true,
       [](double s, std::uint64_t seed) { return near_coincident(scaled(8000, s), seed); }},
      {"dense-32-per-cell", false,
       [](double s, std::uint64_t seed) { return dense(scaled(1 << 16, s), seed); }},
      {"ellipsoids-tangent", true,
       [](double s, std::uint64_t seed) { return ellipsoid_pairs(scaled(16, s), seed); }},
  };
  return families;
}

}  // namespace cg
