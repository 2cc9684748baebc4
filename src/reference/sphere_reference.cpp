// Spheres, exactly (sphere_reference.hpp). The sweep sorts by the lower x bound in long double and
// stops a body's scan at the first body whose lower bound passes its upper bound (+ slack).
#include "reference/sphere_reference.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace cg::exact {

RefContact sphere_contact(std::int64_t a, std::int64_t b, const Vec3<double>& pa, double ra,
                          const Vec3<double>& pb, double rb) {
  RefContact c;
  c.a = a;
  c.b = b;
  const LD ex = LD(pa.x) - pb.x, ey = LD(pa.y) - pb.y, ez = LD(pa.z) - pb.z;
  const LD d = std::sqrt(ex * ex + ey * ey + ez * ez);
  if (d > 0) {
    c.n[0] = ex / d;
    c.n[1] = ey / d;
    c.n[2] = ez / d;
  } else {
    c.n[0] = 1;
    c.n[1] = c.n[2] = 0;
  }
  c.distance = d - (LD(ra) + rb);
  const LD centre_b[3] = {LD(pb.x), LD(pb.y), LD(pb.z)};
  for (int k = 0; k < 3; ++k) {
    c.pb[k] = centre_b[k] + rb * c.n[k];
    c.pa[k] = c.pb[k] + c.n[k] * c.distance;
  }
  return c;
}

std::vector<RefContact> reference_contacts(std::span<const Vec3<double>> p, std::span<const double> r,
                                           LD slack) {
  const std::size_t n = r.size();
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](std::size_t i, std::size_t j) { return LD(p[i].x) - r[i] < LD(p[j].x) - r[j]; });
  std::vector<RefContact> out;
  for (std::size_t u = 0; u < n; ++u) {
    const std::size_t i = order[u];
    const LD hi = LD(p[i].x) + r[i];
    for (std::size_t v = u + 1; v < n; ++v) {
      const std::size_t j = order[v];
      if (LD(p[j].x) - r[j] > hi + slack) break;
      const LD dx = LD(p[i].x) - p[j].x, dy = LD(p[i].y) - p[j].y, dz = LD(p[i].z) - p[j].z;
      const LD s = LD(r[i]) + r[j];
      if (dx * dx + dy * dy + dz * dz > (s + slack) * (s + slack)) continue;
      const std::size_t a = std::min(i, j), b = std::max(i, j);
      out.push_back(sphere_contact(std::int64_t(a), std::int64_t(b), p[a], r[a], p[b], r[b]));
    }
  }
  std::sort(out.begin(), out.end(),
            [](const RefContact& x, const RefContact& y) { return x.a != y.a ? x.a < y.a : x.b < y.b; });
  return out;
}

}  // namespace cg::exact
