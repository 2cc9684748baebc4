#pragma once
// The oracle for the engine: every pair of bounding spheres with d <= ra + rb, decided in extended
// precision (long double) from the double input, via a sweep along x (exact decisions, any N that
// fits a test). Contact data by CONTRACT §3 in long double.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <span>
#include <vector>

#include "core/vec3.hpp"

namespace cg::test {

struct RefContact {
  std::int64_t a, b;
  long double distance;  // d - (ra + rb)
  long double n[3];      // unit normal from b to a ((1,0,0) for coincident centres)
  long double pa[3], pb[3];
};

inline std::vector<RefContact> reference_contacts(std::span<const Vec3<double>> p, std::span<const double> r,
                                                  long double slack = 0) {
  const std::size_t n = r.size();
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) {
    return (long double)p[i].x - r[i] < (long double)p[j].x - r[j];
  });
  std::vector<RefContact> out;
  for (std::size_t u = 0; u < n; ++u) {
    const std::size_t i = order[u];
    const long double hi = (long double)p[i].x + r[i];
    for (std::size_t v = u + 1; v < n; ++v) {
      const std::size_t j = order[v];
      if ((long double)p[j].x - r[j] > hi + slack) break;
      const long double dx = (long double)p[i].x - p[j].x, dy = (long double)p[i].y - p[j].y,
                        dz = (long double)p[i].z - p[j].z;
      const long double s = (long double)r[i] + r[j];
      const long double d2 = dx * dx + dy * dy + dz * dz;
      if (d2 > (s + slack) * (s + slack)) continue;
      std::size_t a = std::min(i, j), b = std::max(i, j);
      RefContact c;
      c.a = std::int64_t(a);
      c.b = std::int64_t(b);
      const long double ex = (long double)p[a].x - p[b].x, ey = (long double)p[a].y - p[b].y,
                        ez = (long double)p[a].z - p[b].z;
      const long double d = std::sqrt(d2);
      if (d > 0) {
        c.n[0] = ex / d;
        c.n[1] = ey / d;
        c.n[2] = ez / d;
      } else {
        c.n[0] = 1;
        c.n[1] = c.n[2] = 0;
      }
      c.distance = d - s;
      const long double pb[3] = {(long double)p[b].x, (long double)p[b].y, (long double)p[b].z};
      for (int k = 0; k < 3; ++k) {
        c.pb[k] = pb[k] + r[b] * c.n[k];
        c.pa[k] = c.pb[k] + c.n[k] * c.distance;
      }
      out.push_back(c);
    }
  }
  std::sort(out.begin(), out.end(),
            [](const RefContact& x, const RefContact& y) { return x.a != y.a ? x.a < y.a : x.b < y.b; });
  return out;
}

}  // namespace cg::test
