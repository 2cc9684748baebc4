// Ellipsoids, exactly (ellipsoid_reference.hpp): the brute-force global minimisation of f and the
// Perram–Wertheim cross-check, in long double.
#include "reference/ellipsoid_reference.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace cg::exact {
namespace {

// G(u, v) = f(m)/|m|, m = n0 + u e1 + v e2 (f is 1-homogeneous, so G = f(m/|m|)).
struct Chart {
  V n0, e1, e2;
  V point(LD u, LD v) const { return add(n0, add(scale(u, e1), scale(v, e2))); }
};
Chart chart_at(V n) {
  const V helper = std::fabs(n.x) < 0.6L ? V{1, 0, 0} : (std::fabs(n.y) < 0.6L ? V{0, 1, 0} : V{0, 0, 1});
  const V e1 = unit(crossp(n, helper));
  return {n, e1, crossp(n, e1)};
}
LD chart_value(const Pair& p, const Chart& c, LD u, LD v) {
  const V m = c.point(u, v);
  return f_value(p, m) / norm(m);
}
std::array<LD, 2> chart_gradient(const Pair& p, const Chart& c, LD u, LD v) {
  const V m = c.point(u, v);
  const LD len = norm(m);
  const V g = f_gradient(p, scale(1 / len, m));  // ∇f is 0-homogeneous
  const LD fv = f_value(p, m);
  return {dotp(g, c.e1) / len - fv * dotp(m, c.e1) / (len * len * len),
          dotp(g, c.e2) / len - fv * dotp(m, c.e2) / (len * len * len)};
}

// Local refinement from n: Newton in the chart at the current point, FD Hessian of the analytic gradient.
V refine(const Pair& p, V n, int iterations = 60) {
  for (int it = 0; it < iterations; ++it) {
    const Chart c = chart_at(n);
    const auto g = chart_gradient(p, c, 0, 0);
    const LD gn = std::hypot(g[0], g[1]);
    if (gn < 1e-17L) break;
    const LD h = 1e-7L;
    const auto gu = chart_gradient(p, c, h, 0), gv = chart_gradient(p, c, 0, h);
    LD h11 = (gu[0] - g[0]) / h, h22 = (gv[1] - g[1]) / h, h12 = 0.5L * ((gu[1] - g[1]) + (gv[0] - g[0])) / h;
    const LD lmin = 0.5L * (h11 + h22) - std::sqrt(0.25L * (h11 - h22) * (h11 - h22) + h12 * h12);
    const LD shift = lmin < 1e-6L ? 1e-6L - lmin : 0;
    h11 += shift;
    h22 += shift;
    const LD det = h11 * h22 - h12 * h12;
    LD su = -(h22 * g[0] - h12 * g[1]) / det, sv = -(h11 * g[1] - h12 * g[0]) / det;
    const LD len = std::hypot(su, sv);
    if (len > 0.3L) {
      su *= 0.3L / len;
      sv *= 0.3L / len;
    }
    const LD f0 = chart_value(p, c, 0, 0);
    bool moved = false;
    for (int k = 0; k < 60; ++k) {
      const LD f1 = chart_value(p, c, su, sv);
      const auto g1 = chart_gradient(p, c, su, sv);
      if (f1 < f0 || (f1 <= f0 + 1e-18L * (1 + std::fabs(f0)) && std::hypot(g1[0], g1[1]) < gn)) {
        n = unit(c.point(su, sv));
        moved = true;
        break;
      }
      su *= 0.5L;
      sv *= 0.5L;
    }
    if (!moved) break;
  }
  return n;
}

}  // namespace

Reference exact_contact(const Pair& p, int samples) {
  struct Cand {
    LD f;
    V n;
  };
  std::vector<Cand> cand;
  cand.reserve(samples + 12);
  const LD golden = 3.14159265358979323846264338327950288L * (3 - std::sqrt(5.0L));
  for (int i = 0; i < samples; ++i) {
    const LD z = 1 - (2 * i + 1) / LD(samples);
    const LD rad = std::sqrt(1 - z * z), phi = golden * i;
    const V n{rad * std::cos(phi), rad * std::sin(phi), z};
    cand.push_back({f_value(p, n), n});
  }
  for (const Body* b : {&p.a, &p.b})
    for (int k = 0; k < 3; ++k)
      for (LD s : {1.0L, -1.0L}) cand.push_back({f_value(p, scale(s, b->axis[k])), scale(s, b->axis[k])});
  std::sort(cand.begin(), cand.end(), [](const Cand& x, const Cand& y) { return x.f < y.f; });
  std::vector<V> seeds;
  for (const Cand& c : cand) {
    bool far = true;
    for (const V& s : seeds) far = far && dotp(s, c.n) < std::cos(0.08L);
    if (far) seeds.push_back(c.n);
    if (seeds.size() >= 16) break;
  }
  std::vector<Cand> minima;
  for (const V& s : seeds) {
    const V n = refine(p, s);
    const LD fv = f_value(p, n);
    bool dup = false;
    for (Cand& m : minima)
      if (dotp(m.n, n) > std::cos(0.01L)) {
        dup = true;
        if (fv < m.f) m = {fv, n};
      }
    if (!dup) minima.push_back({fv, n});
  }
  std::sort(minima.begin(), minima.end(), [](const Cand& x, const Cand& y) { return x.f < y.f; });
  Reference out{};
  out.n = minima[0].n;
  out.distance = -minima[0].f;
  out.position_on_b = add(p.b.centre, support_point(p.b, out.n));
  out.position_on_a = sub(p.a.centre, support_point(p.a, out.n));
  out.minima = int(minima.size());
  out.second_gap = std::numeric_limits<LD>::infinity();
  for (std::size_t i = 1; i < minima.size(); ++i)
    if (dotp(minima[i].n, out.n) < std::cos(0.05L)) {
      out.second_gap = minima[i].f - minima[0].f;
      break;
    }
  return out;
}

// Perram–Wertheim F = max_λ λ(1−λ) rᵀ[(1−λ)A + λB]⁻¹ r, A = Σ_k e_k² axis_k axis_kᵀ, by golden-section
// search on the concave F (200 steps: the bracket shrinks below long-double resolution).
LD pw_exact(const Pair& p) {
  auto cov = [](const Body& b, int i, int j) {
    auto comp = [](V v, int c) { return c == 0 ? v.x : (c == 1 ? v.y : v.z); };
    LD s = 0;
    for (int k = 0; k < 3; ++k) s += semi(b, k) * semi(b, k) * comp(b.axis[k], i) * comp(b.axis[k], j);
    return s;
  };
  LD ma[3][3], mb[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      ma[i][j] = cov(p.a, i, j);
      mb[i][j] = cov(p.b, i, j);
    }
  auto det3 = [](LD m[3][3]) {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
           m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  };
  const LD rv[3] = {p.r.x, p.r.y, p.r.z};
  auto F = [&](LD lam) {
    LD c[3][3];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) c[i][j] = (1 - lam) * ma[i][j] + lam * mb[i][j];
    const LD d = det3(c);
    LD quad = 0;  // rᵀ C⁻¹ r by Cramer: x_i = det(C with column i replaced by r) / det C
    for (int i = 0; i < 3; ++i) {
      LD ci[3][3];
      for (int row = 0; row < 3; ++row)
        for (int col = 0; col < 3; ++col) ci[row][col] = col == i ? rv[row] : c[row][col];
      quad += rv[i] * det3(ci) / d;
    }
    return lam * (1 - lam) * quad;
  };
  const LD g = (std::sqrt(5.0L) - 1) / 2;
  LD lo = 0, hi = 1, x1 = hi - g * (hi - lo), x2 = lo + g * (hi - lo), f1 = F(x1), f2 = F(x2);
  for (int it = 0; it < 200; ++it) {
    if (f1 < f2) {
      lo = x1;
      x1 = x2;
      f1 = f2;
      x2 = lo + g * (hi - lo);
      f2 = F(x2);
    } else {
      hi = x2;
      x2 = x1;
      f2 = f1;
      x1 = hi - g * (hi - lo);
      f1 = F(x1);
    }
  }
  return std::max(f1, f2);
}

}  // namespace cg::exact
