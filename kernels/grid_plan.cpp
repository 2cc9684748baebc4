// Bounds and validation of host bodies, the shared frame and its cell-size model, the grid plan.
#include "grid_plan.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

#include "backend.hpp"  // bits_for
#include "errors.hpp"

namespace cg {

void Bounds::merge(const Bounds& o) {
  if (o.count == 0) return;
  if (count == 0) {
    *this = o;
    return;
  }
  lo = {std::min(lo.x, o.lo.x), std::min(lo.y, o.lo.y), std::min(lo.z, o.lo.z)};
  hi = {std::max(hi.x, o.hi.x), std::max(hi.y, o.hi.y), std::max(hi.z, o.hi.z)};
  r_max = std::max(r_max, o.r_max);
  r_min = std::min(r_min, o.r_min);
  count += o.count;
  for (int k = 0; k < 3; ++k) r_sum[k] += o.r_sum[k];
}

Bounds compute_bounds(const BodiesView& bodies) {
  const std::size_t n = bodies.size();
  if (bodies.position.size() != n)
    throw InputError("bodies: " + std::to_string(bodies.position.size()) + " positions but " +
                     std::to_string(n) + " radii");
  if (!bodies.id.empty() && bodies.id.size() != n) throw InputError("bodies: id array has the wrong size");
  if (!bodies.report.empty() && bodies.report.size() != n)
    throw InputError("bodies: report mask has the wrong size");
  Bounds b;
  b.count = n;
  if (n == 0) return b;
  constexpr double inf = std::numeric_limits<double>::infinity();
  b.lo = {inf, inf, inf};
  b.hi = {-inf, -inf, -inf};
  b.r_min = inf;
  auto id_of = [&](std::size_t i) { return bodies.id.empty() ? std::int64_t(i) : bodies.id[i]; };
  auto bad = [&](std::size_t i) {
    const Vec3<double> p = bodies.position[i];
    const double r = bodies.radius[i];
    return !std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z) || !(r > 0) ||
           !std::isfinite(r) || (i > 0 && !bodies.id.empty() && !(bodies.id[i] > bodies.id[i - 1]));
  };
  // Parallel: per chunk the bounds (min / max are exact, so the fold order does not matter: every
  // lower bound p - r and upper bound p + r of a valid body is a +0 or a non-zero value) and the first
  // bad body; the smallest bad index over the chunks is reported, as a sequential scan would.
  const int threads = n < (std::size_t(1) << 15) ? 1 : omp_get_max_threads();
  std::vector<Bounds> part(static_cast<std::size_t>(threads), b);
  std::vector<std::size_t> first_bad(static_cast<std::size_t>(threads), n);
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (threads > 1)
  for (int t = 0; t < threads; ++t) {
    const std::size_t begin = n * std::size_t(t) / std::size_t(threads),
                      end = n * std::size_t(t + 1) / std::size_t(threads);
    Vec3<double> lo = b.lo, hi = b.hi;
    double r_max = 0, r_min = std::numeric_limits<double>::infinity(), s1 = 0, s2 = 0, s3 = 0;
    for (std::size_t i = begin; i < end; ++i) {
      if (bad(i)) {
        first_bad[static_cast<std::size_t>(t)] = i;
        break;
      }
      const Vec3<double> p = bodies.position[i];
      const double r = bodies.radius[i];
      lo = {std::min(lo.x, p.x - r), std::min(lo.y, p.y - r), std::min(lo.z, p.z - r)};
      hi = {std::max(hi.x, p.x + r), std::max(hi.y, p.y + r), std::max(hi.z, p.z + r)};
      r_max = std::max(r_max, r);
      r_min = std::min(r_min, r);
      s1 += r;
      s2 += r * r;
      s3 += r * r * r;
    }
    part[static_cast<std::size_t>(t)].r_sum[0] = s1;
    part[static_cast<std::size_t>(t)].r_sum[1] = s2;
    part[static_cast<std::size_t>(t)].r_sum[2] = s3;
    part[static_cast<std::size_t>(t)].lo = lo;
    part[static_cast<std::size_t>(t)].hi = hi;
    part[static_cast<std::size_t>(t)].r_max = r_max;
    part[static_cast<std::size_t>(t)].r_min = r_min;
  }
  const std::size_t i = *std::min_element(first_bad.begin(), first_bad.end());
  if (i < n) {
    const Vec3<double> p = bodies.position[i];
    const double r = bodies.radius[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
      std::ostringstream m;
      m << "body " << id_of(i) << ": centre (" << p.x << ", " << p.y << ", " << p.z << ") is not finite";
      throw InputError(m.str());
    }
    if (!(r > 0) || !std::isfinite(r)) {
      std::ostringstream m;
      m << "body " << id_of(i) << ": radius " << r << " is not a finite value > 0";
      throw InputError(m.str());
    }
    throw InputError("bodies: ids are not strictly ascending at index " + std::to_string(i));
  }
  for (const Bounds& q : part) {
    b.lo = {std::min(b.lo.x, q.lo.x), std::min(b.lo.y, q.lo.y), std::min(b.lo.z, q.lo.z)};
    b.hi = {std::max(b.hi.x, q.hi.x), std::max(b.hi.y, q.hi.y), std::max(b.hi.z, q.hi.z)};
    b.r_max = std::max(b.r_max, q.r_max);
    b.r_min = std::min(b.r_min, q.r_min);
    for (int k = 0; k < 3; ++k) b.r_sum[k] += q.r_sum[k];
  }
  return b;
}

bool ids_ascending(std::span<const std::int64_t> id, int threads) {
  const std::size_t n = id.size();
  const int nt = threads > 0 ? threads : omp_get_max_threads();
  int ok = 1;
#pragma omp parallel for num_threads(nt) schedule(static) reduction(& : ok) if (n > (std::size_t(1) << 15))
  for (std::size_t i = 1; i < n; ++i) ok &= id[i] > id[i - 1] ? 1 : 0;
  return ok != 0;
}

namespace {
// The epsilon of the broad phase's local coordinates.
double real_epsilon(Precision p) {
  return float_broad_phase(p) ? double(std::numeric_limits<float>::epsilon())
                              : std::numeric_limits<double>::epsilon();
}
double max_extent(const Bounds& b) { return std::max({b.hi.x - b.lo.x, b.hi.y - b.lo.y, b.hi.z - b.lo.z}); }
}  // namespace

double broad_margin(const Bounds& b, const Vec3<double>& origin, Precision p) {
  if (p != Precision::mixed || b.count == 0) return 0;
  const double l =
      std::max({std::abs(b.lo.x - origin.x), std::abs(b.lo.y - origin.y), std::abs(b.lo.z - origin.z),
                std::abs(b.hi.x - origin.x), std::abs(b.hi.y - origin.y), std::abs(b.hi.z - origin.z)});
  return 4 * double(std::numeric_limits<float>::epsilon()) * (l + 2 * b.r_max);
}

void check_fp32_world(const Bounds& b, Precision p) {
  if (p != Precision::fp32 || b.count == 0) return;
  const double x = std::max({std::abs(b.lo.x), std::abs(b.lo.y), std::abs(b.lo.z), std::abs(b.hi.x),
                             std::abs(b.hi.y), std::abs(b.hi.z)});
  const double ulp = double(std::nextafter(float(x), std::numeric_limits<float>::infinity()) - float(x));
  if (ulp > b.r_max / 4) {
    std::ostringstream m;
    m << "fp32 writes world positions as float32, whose spacing at the scene's largest coordinate " << x
      << " is " << ulp << ", more than a quarter of the largest radius " << b.r_max
      << "; use --precision mixed or fp64 (float64 output from the world coordinates)";
    throw InputError(m.str());
  }
}

double min_cell_size(const Bounds& b, Precision p) {
  // c ± r is computed in Real in the local frame, where |c| <= extent: each of the two bounds and the
  // product by 1/cell carries a few ulps of rounding. 16 ulps of (extent + 2 r_max) covers them all,
  // so a body never spans three cells along an axis. mixed: of the radius plus broad_margin().
  const double eps = real_epsilon(p);
  const double d = 2.0 * (b.r_max + broad_margin(b, b.lo, p));
  return d * (1.0 + 16 * eps) + 16 * eps * (max_extent(b) + d);
}

double tuned_cell_size(const Bounds& b, Precision p) {
  const double c0 = min_cell_size(b, p);
  if (b.count == 0 || !(b.r_max > 0)) return c0;
  const double n = double(b.count);
  // Mean r, r², r³; bounds without moments (all zero) model every body at r_max.
  double m[3] = {b.r_sum[0] / n, b.r_sum[1] / n, b.r_sum[2] / n};
  if (!(m[0] > 0)) m[0] = b.r_max, m[1] = b.r_max * b.r_max, m[2] = b.r_max * b.r_max * b.r_max;
  const double ext[3] = {b.hi.x - b.lo.x, b.hi.y - b.lo.y, b.hi.z - b.lo.z};
  double best = c0, best_cost = std::numeric_limits<double>::infinity();
  for (int step = 0; step <= 8; ++step) {  // factors 1, 1.25, …, 3: the first minimum wins
    const double c = c0 * (1.0 + 0.25 * step);
    const double u = 2.0 / c;  // E[(1 + u r)³] = 1 + 3u E[r] + 3u² E[r²] + u³ E[r³]
    const double e = 1.0 + 3.0 * u * m[0] + 3.0 * u * u * m[1] + u * u * u * m[2];
    double cells = 1.0;
    for (double x : ext) cells *= std::max(1.0, x / c);
    const double cost = e + kPairWeight * n * e * e / cells;
    if (cost < best_cost) best = c, best_cost = cost;
  }
  return best;
}

Frame make_frame(const Bounds& b, double requested_cell_size, Precision p, CellChoice choice) {
  if (b.count == 0) throw InputError("scene has no bodies");
  check_fp32_world(b, p);
  Frame f;
  f.origin = b.lo;
  const double need = min_cell_size(b, p);
  if (requested_cell_size == 0) {
    f.cell_size = choice == CellChoice::tuned ? tuned_cell_size(b, p) : need;
  } else {
    if (!(requested_cell_size > 0) || !std::isfinite(requested_cell_size))
      throw UsageError("--cell-size must be a finite value > 0");
    if (requested_cell_size < need) {
      std::ostringstream m;
      m.precision(17);
      m << "--cell-size " << requested_cell_size << " is smaller than the largest bounding diameter "
        << 2 * b.r_max << " plus its rounding margin (" << need << ")";
      throw UsageError(m.str());
    }
    f.cell_size = requested_cell_size;
  }
  return f;
}

GridPlan plan_grid(const Bounds& local, const Frame& frame, Precision p) {
  GridPlan g;
  g.frame = frame;
  if (local.count == 0) return g;
  // Per axis, the frame cell coordinates the local bodies can produce, with one cell of slack for
  // rounding on each side; base rounded down to even so cell parity (type) is the frame's.
  const double lim = float_broad_phase(p) ? double(1u << 22) : double(1u << 31) - 4;
  const double lo[3] = {local.lo.x - frame.origin.x, local.lo.y - frame.origin.y,
                        local.lo.z - frame.origin.z};
  const double hi[3] = {local.hi.x - frame.origin.x, local.hi.y - frame.origin.y,
                        local.hi.z - frame.origin.z};
  for (int k = 0; k < 3; ++k) {
    const double c_hi = std::floor(hi[k] / frame.cell_size) + 1;
    if (!(c_hi < lim)) {
      std::ostringstream m;
      m << "the scene spans " << c_hi << " cells of edge " << frame.cell_size << " along axis "
        << "xyz"[k] << ", more than the " << lim << " that " << to_string(p)
        << " local coordinates resolve; use --precision fp64 or a larger --cell-size";
      throw InputError(m.str());
    }
    double c_lo = std::max(0.0, std::floor(lo[k] / frame.cell_size) - 1);
    auto base = static_cast<std::uint32_t>(c_lo) & ~1u;
    g.base[k] = base;
    g.dims[k] = static_cast<std::uint32_t>(c_hi) - base + 1;
    g.half[k] = (g.dims[k] + 1) / 2;
  }
  const long double cells = (long double)g.half[0] * g.half[1] * g.half[2];
  if (cells > (long double)(std::uint64_t(1) << 60)) {
    std::ostringstream m;
    m << "the grid needs " << double(cells) * 8 << " cells (" << g.dims[0] << " x " << g.dims[1] << " x "
      << g.dims[2] << "), more than a 64-bit cell key encodes; use a larger --cell-size";
    throw InputError(m.str());
  }
  g.half_bits = detail::bits_for(std::uint64_t(g.half[0]) * g.half[1] * g.half[2]);
  g.key_bits = g.half_bits + 3;
  g.key64 = g.key_bits > 32;
  return g;
}

}  // namespace cg
