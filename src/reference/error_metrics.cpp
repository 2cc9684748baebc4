// The comparison with the exact reference (error_metrics.hpp): one merge of two (a, b)-sorted lists.
#include "reference/error_metrics.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace cg::exact {
namespace {

double point_error(const Vec3<double>& p, const LD q[3]) {
  const LD dx = LD(p.x) - q[0], dy = LD(p.y) - q[1], dz = LD(p.z) - q[2];
  return double(std::sqrt(dx * dx + dy * dy + dz * dz));
}

Vec3<double> to_double(const LD v[3]) { return {double(v[0]), double(v[1]), double(v[2])}; }

// The larger error; a NaN error is infinitely large (never hidden by max).
double worse(double current, double value) { return std::isnan(value) ? HUGE_VAL : std::max(current, value); }

// Nearest-rank 99th percentile (0 for none).
double p99(std::vector<double> v) {
  if (v.empty()) return 0;
  const std::size_t rank = std::size_t(std::ceil(0.99 * double(v.size())));
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(rank - 1), v.end());
  return v[rank - 1];
}

}  // namespace

double angle_deg(Vec3<double> u, Vec3<double> v) {
  const Vec3<double> c{u.y * v.z - u.z * v.y, u.z * v.x - u.x * v.z, u.x * v.y - u.y * v.x};
  const double s = std::sqrt(c.x * c.x + c.y * c.y + c.z * c.z), d = u.x * v.x + u.y * v.y + u.z * v.z;
  return std::atan2(s, d) * 180 / std::numbers::pi;
}

ContactErrors compare_with_reference(std::span<const FoundContact> found,
                                     std::span<const RefContact> reference, std::span<const double> radius,
                                     double band) {
  ContactErrors e;
  e.reported = found.size();
  e.reference = reference.size();
  std::vector<double> position;
  auto before = [](std::int64_t a1, std::int64_t b1, std::int64_t a2, std::int64_t b2) {
    return a1 != a2 ? a1 < a2 : b1 < b2;
  };
  std::size_t i = 0, j = 0;
  while (i < found.size() || j < reference.size()) {
    const bool take_found =
        j == reference.size() ||
        (i < found.size() && before(found[i].a, found[i].b, reference[j].a, reference[j].b));
    const bool take_ref = i == found.size() || (j < reference.size() && before(reference[j].a, reference[j].b,
                                                                               found[i].a, found[i].b));
    if (take_found) {  // not within the band of the reference: beyond it
      ++e.extra;
      ++i;
      continue;
    }
    const RefContact& r = reference[j++];
    const bool borderline = std::fabs(r.distance) <= LD(band);
    e.borderline += borderline;
    if (take_ref) {
      e.missed += !borderline && r.distance < 0;
      continue;
    }
    const FoundContact& f = found[i++];
    if (!borderline && r.distance > 0) {  // held by a wider reference, but beyond this band
      ++e.extra;
      continue;
    }
    ++e.matched;
    const double pos = std::max(point_error(f.pa, r.pa) / radius[std::size_t(f.a)],
                                point_error(f.pb, r.pb) / radius[std::size_t(f.b)]);
    position.push_back(std::isnan(pos) ? HUGE_VAL : pos);
    e.max_position_rel = worse(e.max_position_rel, pos);
    e.max_normal_deg = worse(e.max_normal_deg, angle_deg(f.n, to_double(r.n)));
    e.max_distance = worse(e.max_distance, double(std::fabs(LD(f.distance) - r.distance)));
  }
  e.p99_position_rel = p99(std::move(position));
  return e;
}

}  // namespace cg::exact
