// generate.cpp: seeded scene generators and the density model that sizes their box.
//
// Randomness: the counter-based generator of counter_rng.hpp, so body i does not depend on chunking,
// threads or entry point, and generate_scene == generate_scene_file. The scenes the tests build by
// hand (make_clustered_scene, make_ellipsoid_scene) are in test_scenes.cpp.
//
// Density model: two bodies with centres independent and uniform in a cube of edge L touch iff
// |c1 - c2| <= r1 + r2, which has probability P((r1 + r2)/L), P the distance CDF of two uniform points
// of the unit cube. P(t) = 4π/3·t³ − 3π/2·t⁴ + 8/5·t⁵ − 1/6·t⁶ is exact for t <= 1; for 1 < t < √3
// we use the exact integral P(t) = 8∫∫(1−u)(1−v)F(min(1, √(t²−u²−v²)₊)) du dv, F(a) = a − a²/2,
// whose inner integral has a closed form and whose outer one is done by Gauss–Legendre (tabulated
// once, linear interpolation, error < 1e-7); P = 1 from √3 on. So P is continuous and monotone and
// the box edge is well defined even for tiny n (where t > 1 matters). E[P((r1+r2)/L)] over the
// radius law is a 128×128-node composite Gauss–Legendre quadrature in the law's uniform variable.
// The edge solves (n−1)/2 · E[P] = c by bisection in log L (E decreases in L).
#include "scene/generate.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <mutex>
#include <numbers>
#include <vector>

#include "errors.hpp"
#include "io/scene_file.hpp"
#include "run/progress.hpp"
#include "scene/counter_rng.hpp"

namespace cg {
namespace {

using namespace scene_rng;

constexpr const char* kSoftwareVersion = CONTACTGRID_VERSION;
constexpr std::size_t kWriteChunk = std::size_t(1) << 20;  // bodies per streamed block

// ---- quadrature --------------------------------------------------------------------------------

struct Rule {
  std::vector<double> x, w;  // nodes and weights on [0, 1]
};

// m-point Gauss–Legendre on [0, 1] (Newton on the Legendre polynomial).
Rule gauss_legendre(int m) {
  Rule rule;
  rule.x.resize(m);
  rule.w.resize(m);
  for (int i = 0; i < (m + 1) / 2; ++i) {
    double z = std::cos(std::numbers::pi * (i + 0.75) / (m + 0.5));
    double dp = 0;
    for (int iteration = 0; iteration < 100; ++iteration) {
      double p0 = 1, p1 = 0;
      for (int j = 1; j <= m; ++j) {
        double p2 = p1;
        p1 = p0;
        p0 = ((2.0 * j - 1) * z * p1 - (j - 1.0) * p2) / j;
      }
      dp = m * (z * p0 - p1) / (z * z - 1);
      double dz = p0 / dp;
      z -= dz;
      if (std::abs(dz) < 1e-16) break;
    }
    double weight = 2 / ((1 - z * z) * dp * dp);
    rule.x[i] = 0.5 * (1 - z);
    rule.x[m - 1 - i] = 0.5 * (1 + z);
    rule.w[i] = rule.w[m - 1 - i] = 0.5 * weight;
  }
  return rule;
}

const Rule& rule64() {
  static const Rule rule = gauss_legendre(64);
  return rule;
}

// ∫_0^1 (1−x)·F(min(1, √(s − x²)₊)) dx in closed form (F(a) = a − a²/2).
double inner_integral(double s) {
  if (s <= 0) return 0;
  double x1 = std::clamp(std::sqrt(std::max(0.0, s - 1)), 0.0, 1.0);  // a = 1 up to here
  double x2 = std::clamp(std::sqrt(s), 0.0, 1.0);                     // a = 0 from here
  double root_s = std::sqrt(s);
  auto antiderivative = [&](double x) {                     // of (1−x)(√(s−x²) − (s−x²)/2)
    double q = std::max(0.0, (root_s - x) * (root_s + x));  // s − x², exactly 0 at x = √s
    double a = 0.5 * (x * std::sqrt(q) + s * std::asin(std::min(1.0, x / root_s)));
    double b = -q * std::sqrt(q) / 3;
    double c = 0.5 * (s * x - x * x * x / 3 - s * x * x / 2 + x * x * x * x / 4);
    return a - b - c;
  };
  double flat = 0.5 * (x1 - x1 * x1 / 2);
  return flat + (antiderivative(x2) - antiderivative(x1));
}

// ∫_a^b f by 64-point Gauss–Legendre after x = a + (b−a)·τ²(3−2τ), which smooths the square-root
// behaviour of the integrand at the pieces' ends.
template <class F>
double smooth_integral(double a, double b, F f) {
  if (!(b > a)) return 0;
  const Rule& r = rule64();
  double sum = 0;
  for (std::size_t k = 0; k < r.x.size(); ++k) {
    double tau = r.x[k];
    double phi = tau * tau * (3 - 2 * tau), dphi = 6 * tau * (1 - tau);
    sum += r.w[k] * dphi * f(a + (b - a) * phi);
  }
  return sum * (b - a);
}

double cdf_polynomial(double t) {
  using std::numbers::pi;
  double t3 = t * t * t;
  return t3 * (4 * pi / 3 + t * (-1.5 * pi + t * (8.0 / 5 + t * (-1.0 / 6))));
}

constexpr int kTableIntervals = 2048;

const std::vector<double>& cdf_table() {  // P on [1, √3], kTableIntervals + 1 points
  static const std::vector<double> table = [] {
    std::vector<double> values(kTableIntervals + 1);
    const double lo = 1, hi = std::sqrt(3.0);
    for (int i = 0; i <= kTableIntervals; ++i) {
      values[i] = detail::cube_distance_cdf_integral(lo + (hi - lo) * i / kTableIntervals);
    }
    values[kTableIntervals] = 1;
    for (int i = 1; i <= kTableIntervals; ++i) values[i] = std::max(values[i], values[i - 1]);  // monotone
    return values;
  }();
  return table;
}

// Radius quadrature: nodes r_k with weights (sum 1) for the law on [r_low, r_high].
struct RadiusNodes {
  std::vector<double> r, w;
};

RadiusNodes radius_nodes(RadiusLaw law, double r_low, double r_high) {
  constexpr int kPanels = 16, kPerPanel = 8;
  static const Rule rule = gauss_legendre(kPerPanel);
  RadiusNodes nodes;
  double log_ratio = std::log(r_high / r_low);
  for (int p = 0; p < kPanels; ++p) {
    for (int k = 0; k < kPerPanel; ++k) {
      double v = (p + rule.x[k]) / kPanels;
      double r = law == RadiusLaw::uniform       ? r_low + (r_high - r_low) * v
                 : law == RadiusLaw::log_uniform ? r_low * std::exp(v * log_ratio)
                                                 : r_low + (r_high - r_low) * std::cbrt(v);  // max of 3
      nodes.r.push_back(std::clamp(r, r_low, r_high));
      nodes.w.push_back(rule.w[k] / kPanels);
    }
  }
  return nodes;
}

double expected_contact(const RadiusNodes& nodes, double edge) {
  double sum = 0;
  for (std::size_t i = 0; i < nodes.r.size(); ++i) {
    double row = 0;
    for (std::size_t j = 0; j < nodes.r.size(); ++j)
      row += nodes.w[j] * cube_distance_cdf((nodes.r[i] + nodes.r[j]) / edge);
    sum += nodes.w[i] * row;
  }
  return sum;
}

void check_radius_law(double r_low, double r_high) {
  if (!(std::isfinite(r_low) && std::isfinite(r_high) && r_low > 0 && r_low <= r_high)) {
    throw UsageError(
        fmt::format("radii must satisfy 0 < radius_low <= radius_high (got {} and {})", r_low, r_high));
  }
}

// ---- bodies ------------------------------------------------------------------------------------

double box_edge_of(std::uint64_t n, const RadiusNodes& nodes, double r_low, double contacts_per_body);

// Everything that defines body i of a generated scene.
struct BodyLaw {
  CounterRng rng;
  bool log_uniform = false;
  bool two_sizes = false;  // bimodal, intruders: r_high for `large` of the `count` bodies, else r_low
  std::uint64_t large = 0, count = 0;
  double edge = 1, r_low = 0.5, r_high = 1, log_ratio = 0;
  Vec3<double> offset{0, 0, 0};

  double coordinate(std::uint64_t i, unsigned stream, double origin) const {
    double x = std::min(edge * rng.unit(i, stream), std::nextafter(edge, 0.0));  // in [0, L)
    return origin + x;
  }
  void ellipsoid(std::uint64_t i, Vec3<double>& centre, Vec3<double>& semi_axes,
                 std::array<double, 4>& orientation) const;
  void body(std::uint64_t i, Vec3<double>& centre, double& radius) const {
    centre = {coordinate(i, kX, offset.x), coordinate(i, kY, offset.y), coordinate(i, kZ, offset.z)};
    if (two_sizes) {
      radius = generated_is_large(i, large, count) ? r_high : r_low;
      return;
    }
    double u = rng.unit(i, kRadius);
    double r = log_uniform ? r_low * std::exp(u * log_ratio) : r_low + (r_high - r_low) * u;
    radius = std::clamp(r, r_low, r_high);
  }
};

bool two_size_kind(const std::string& kind) { return kind == "bimodal" || kind == "intruders"; }

BodyLaw body_law(const GenerateOptions& o, double edge) {
  BodyLaw law{CounterRng(o.seed)};
  law.log_uniform = o.kind == "polydisperse";
  law.two_sizes = two_size_kind(o.kind);
  law.large = generated_large(o);
  law.count = o.count;
  law.edge = edge;
  law.r_low = o.radius_low;
  law.r_high = o.radius_high;
  law.log_ratio = std::log(o.radius_high / o.radius_low);
  law.offset = o.offset;
  return law;
}

void BodyLaw::ellipsoid(std::uint64_t i, Vec3<double>& centre, Vec3<double>& semi_axes,
                        std::array<double, 4>& orientation) const {
  centre = {coordinate(i, kX, offset.x), coordinate(i, kY, offset.y), coordinate(i, kZ, offset.z)};
  auto axis = [&](unsigned stream) {
    return std::clamp(r_low + (r_high - r_low) * rng.unit(i, stream), r_low, r_high);
  };
  semi_axes = {axis(kAxisA), axis(kAxisB), axis(kAxisC)};
  orientation = random_quaternion(rng, i);
}

Attributes generator_attributes(const GenerateOptions& o, double edge) {
  Attributes a;
  const std::uint64_t e = generated_ellipsoids(o);
  if (o.kind == "ellipsoids" || o.kind == "mixed") {
    a["spheres"] = static_cast<std::int64_t>(o.count - e);
    a["ellipsoids"] = static_cast<std::int64_t>(e);
  }
  if (o.kind == "mixed") a["ellipsoid_fraction"] = o.ellipsoid_fraction;
  if (two_size_kind(o.kind)) a["large"] = static_cast<std::int64_t>(generated_large(o));
  if (o.kind == "bimodal") a["large_fraction"] = o.large_fraction;
  if (o.kind == "intruders") a["intruders"] = static_cast<std::int64_t>(o.intruders);
  a["generator"] = o.kind;
  a["count"] = static_cast<std::int64_t>(o.count);
  a["seed"] = std::bit_cast<std::int64_t>(o.seed);  // seeds >= 2^63 read back negative: bit-cast
  a["contacts_per_body"] = o.contacts_per_body;
  a["box_edge"] = edge;
  a["offset_x"] = o.offset.x;
  a["offset_y"] = o.offset.y;
  a["offset_z"] = o.offset.z;
  a["software_version"] = std::string(kSoftwareVersion);
  return a;
}

}  // namespace

// ---- density model -------------------------------------------------------------------------------

double detail::cube_distance_cdf_integral(double t) {
  if (!(t > 0)) return 0;
  double t2 = t * t;
  std::vector<double> cuts{0.0, 1.0};
  for (double c : {t2 - 2, t2 - 1, t2}) {
    if (c > 0 && std::sqrt(c) < 1) cuts.push_back(std::sqrt(c));
  }
  std::sort(cuts.begin(), cuts.end());
  double sum = 0;
  for (std::size_t k = 0; k + 1 < cuts.size(); ++k) {
    sum +=
        smooth_integral(cuts[k], cuts[k + 1], [&](double u) { return (1 - u) * inner_integral(t2 - u * u); });
  }
  return std::min(1.0, 8 * sum);
}

double cube_distance_cdf(double t) {
  if (!(t > 0)) return 0;  // also NaN
  if (t <= 1) return std::min(cdf_polynomial(t), cdf_table()[0]);
  if (t >= std::sqrt(3.0)) return 1;
  const std::vector<double>& table = cdf_table();
  double position = (t - 1) / (std::sqrt(3.0) - 1) * kTableIntervals;
  int i = std::min(static_cast<int>(position), kTableIntervals - 1);
  double f = position - i;
  return table[i] + f * (table[i + 1] - table[i]);
}

double expected_pair_contact(double edge, RadiusLaw law, double r_low, double r_high) {
  check_radius_law(r_low, r_high);
  if (!(edge > 0)) throw UsageError(fmt::format("box edge must be > 0 (got {})", edge));
  return expected_contact(radius_nodes(law, r_low, r_high), edge);
}

double box_edge(std::uint64_t n, RadiusLaw law, double r_low, double r_high, double contacts_per_body) {
  check_radius_law(r_low, r_high);
  if (n == 0) throw UsageError("box edge: body count must be >= 1");
  if (!(std::isfinite(contacts_per_body) && contacts_per_body > 0))
    throw UsageError(
        fmt::format("contacts per body must be a finite number > 0 (got {})", contacts_per_body));
  return box_edge_of(n, radius_nodes(law, r_low, r_high), r_low, contacts_per_body);
}

namespace {
// The edge for radii with the quadrature `nodes` (arguments checked by the callers).
double box_edge_of(std::uint64_t n, const RadiusNodes& nodes, double r_low, double contacts_per_body) {
  const double pairs_per_body = 0.5 * static_cast<double>(n - 1);
  auto excess = [&](double edge) {
    return pairs_per_body * expected_contact(nodes, edge) - contacts_per_body;
  };

  double lo = 2 * r_low / std::sqrt(3.0);  // every pair in contact at this edge and below
  if (excess(lo) <= 0) return lo;

  double s3 = 0;  // E[(r1 + r2)^3]: the small-t asymptote E[P] ≈ 4π/3·E[s³]/L³ gives the scale
  for (std::size_t i = 0; i < nodes.r.size(); ++i)
    for (std::size_t j = 0; j < nodes.r.size(); ++j)
      s3 += nodes.w[i] * nodes.w[j] * std::pow(nodes.r[i] + nodes.r[j], 3);
  double hi =
      std::max(2 * lo, 2 * std::cbrt(pairs_per_body * 4 * std::numbers::pi / 3 * s3 / contacts_per_body));
  for (int k = 0; k < 200 && excess(hi) > 0; ++k) hi *= 2;

  for (int k = 0; k < 200 && hi > lo * (1 + 1e-15); ++k) {
    double mid = std::sqrt(lo * hi);
    if (mid <= lo || mid >= hi) break;
    (excess(mid) > 0 ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}
}  // namespace

double uniform_box_edge(std::uint64_t n, double r_low, double r_high, double contacts_per_body) {
  return box_edge(n, RadiusLaw::uniform, r_low, r_high, contacts_per_body);
}

double polydisperse_box_edge(std::uint64_t n, double r_low, double r_high, double contacts_per_body) {
  return box_edge(n, RadiusLaw::log_uniform, r_low, r_high, contacts_per_body);
}

bool is_pour(const GenerateOptions& o) { return o.kind == "pour" || o.kind == "pour-ellipsoids"; }

std::uint64_t generated_ellipsoids(const GenerateOptions& o) {
  if (o.kind == "ellipsoids" || o.kind == "pour-ellipsoids") return o.count;
  if (o.kind != "mixed") return 0;
  const double m = std::round(o.ellipsoid_fraction * static_cast<double>(o.count));
  return std::min(o.count, static_cast<std::uint64_t>(std::max(0.0, m)));
}

std::uint64_t generated_large(const GenerateOptions& o) {
  if (o.kind == "intruders") return std::min(o.intruders, o.count);
  if (o.kind != "bimodal" || !(o.large_fraction > 0)) return 0;
  if (!(o.large_fraction < 1)) return o.count;
  const double size = o.radius_low / o.radius_high;
  const double x = o.large_fraction / (1 - o.large_fraction) * size * size * size;
  const double k = std::round(static_cast<double>(o.count) * (x / (1 + x)));
  return std::min(o.count, static_cast<std::uint64_t>(std::max(0.0, k)));
}

bool generated_is_large(std::uint64_t i, std::uint64_t large, std::uint64_t count) {
  // i, large, count <= 2^28: the products stay below 2^57
  return (i + 1) * large / count > i * large / count;
}

void validate_generate_options(const GenerateOptions& o) {
  if (o.kind != "uniform" && o.kind != "polydisperse" && o.kind != "ellipsoids" && o.kind != "mixed" &&
      !two_size_kind(o.kind) && !is_pour(o))
    throw UsageError(fmt::format(
        "generator kind must be uniform, polydisperse, ellipsoids, mixed, bimodal, intruders, pour "
        "or pour-ellipsoids (got \"{}\")",
        o.kind));
  if (o.kind == "mixed" && !(o.ellipsoid_fraction >= 0 && o.ellipsoid_fraction <= 1))
    throw UsageError(fmt::format("ellipsoid fraction must be in [0, 1] (got {})", o.ellipsoid_fraction));
  if (is_pour(o) && !(o.pour_spacing >= 1.5 && o.pour_spacing <= 10))
    throw UsageError(fmt::format("pour spacing must be in [1.5, 10] (got {})", o.pour_spacing));
  if (o.kind == "bimodal" && !(o.large_fraction >= 0 && o.large_fraction <= 1))
    throw UsageError(fmt::format("large fraction must be in [0, 1] (got {})", o.large_fraction));
  if (o.count < 1 || o.count > kMaxGenerateCount)
    throw UsageError(
        fmt::format("body count must be in [1, 2^28 = {}] (got {})", kMaxGenerateCount, o.count));
  if (o.kind == "intruders" && (o.intruders < 1 || o.intruders > o.count))
    throw UsageError(fmt::format("intruders must be in [1, count = {}] (got {})", o.count, o.intruders));
  check_radius_law(o.radius_low, o.radius_high);
  if ((o.kind == "polydisperse" || two_size_kind(o.kind)) &&
      o.radius_high / o.radius_low > kMaxPolydisperseRatio) {
    throw UsageError(fmt::format("{} radius ratio {} / {} = {} exceeds {}", o.kind, o.radius_high,
                                 o.radius_low, o.radius_high / o.radius_low, kMaxPolydisperseRatio));
  }
  if (!(std::isfinite(o.contacts_per_body) && o.contacts_per_body > 0))
    throw UsageError(
        fmt::format("contacts per body must be a finite number > 0 (got {})", o.contacts_per_body));
  if (!(std::isfinite(o.offset.x) && std::isfinite(o.offset.y) && std::isfinite(o.offset.z)))
    throw UsageError("offset must be finite");
}

double scene_box_edge(const GenerateOptions& o) {
  validate_generate_options(o);
  if (o.kind == "mixed") {  // the bounding radii: a mixture of the two laws
    const double f = static_cast<double>(generated_ellipsoids(o)) / static_cast<double>(o.count);
    RadiusNodes nodes = radius_nodes(RadiusLaw::uniform, o.radius_low, o.radius_high);
    const RadiusNodes e = radius_nodes(RadiusLaw::max_of_three_uniform, o.radius_low, o.radius_high);
    for (double& w : nodes.w) w *= 1 - f;
    for (std::size_t k = 0; k < e.r.size(); ++k) {
      nodes.r.push_back(e.r[k]);
      nodes.w.push_back(f * e.w[k]);
    }
    return box_edge_of(o.count, nodes, o.radius_low, o.contacts_per_body);
  }
  if (o.kind == "intruders") {  // the grains' own density; the intruders add their contacts
    const std::uint64_t small = o.count - generated_large(o);
    return small > 0
               ? box_edge(small, RadiusLaw::uniform, o.radius_low, o.radius_low, o.contacts_per_body)
               : box_edge(o.count, RadiusLaw::uniform, o.radius_high, o.radius_high, o.contacts_per_body);
  }
  if (o.kind == "bimodal") {  // two point masses: the share of large bodies by count
    const double q = static_cast<double>(generated_large(o)) / static_cast<double>(o.count);
    const RadiusNodes nodes{{o.radius_low, o.radius_high}, {1 - q, q}};
    return box_edge_of(o.count, nodes, o.radius_low, o.contacts_per_body);
  }
  RadiusLaw law = o.kind == "polydisperse" ? RadiusLaw::log_uniform
                  : o.kind == "ellipsoids" ? RadiusLaw::max_of_three_uniform
                                           : RadiusLaw::uniform;
  return box_edge(o.count, law, o.radius_low, o.radius_high, o.contacts_per_body);
}

// ---- generators ------------------------------------------------------------------------------------

Scene generate_scene(const GenerateOptions& options) {
  const double edge = scene_box_edge(options);
  const BodyLaw law = body_law(options, edge);
  const std::uint64_t e = generated_ellipsoids(options), n = options.count - e;
  Scene scene;
  scene.sphere_position.resize(n);
  scene.sphere_radius.resize(n);
  for (std::uint64_t i = 0; i < n; ++i) law.body(i, scene.sphere_position[i], scene.sphere_radius[i]);
  scene.ellipsoid_position.resize(e);
  scene.ellipsoid_semi_axes.resize(e);
  scene.ellipsoid_orientation.resize(e);
  for (std::uint64_t j = 0; j < e; ++j)
    law.ellipsoid(n + j, scene.ellipsoid_position[j], scene.ellipsoid_semi_axes[j],
                  scene.ellipsoid_orientation[j]);
  scene.radius_low = options.radius_low;
  scene.radius_high = options.radius_high;
  scene.attributes = generator_attributes(options, edge);
  return scene;
}

// A granular pour (generate.hpp): a column of bodies on a jittered cubic lattice above a floor, in an
// open box whose walls the scene names for contactgrid simulate.
Scene generate_pour(const GenerateOptions& o) {
  validate_generate_options(o);
  const CounterRng rng(o.seed);
  const bool ellipsoids = o.kind == "pour-ellipsoids";
  const double s = o.pour_spacing * o.radius_high;  // lattice spacing
  // jitter: 2 % of the spacing while the bodies are apart; pressed together, a tenth of the overlap of
  // two largest bodies, so that every neighbour stays in contact
  const double amplitude = o.pour_spacing >= 2 ? 0.02 * s : 0.1 * (2 * o.radius_high - s);
  const std::uint64_t m = std::max<std::uint64_t>(
      1, static_cast<std::uint64_t>(std::ceil(std::cbrt(static_cast<double>(o.count) / 2))));
  const std::uint64_t layers = (o.count + m * m - 1) / (m * m);
  const double width = static_cast<double>(m) * s, height = static_cast<double>(layers + 1) * s;
  Scene scene;
  for (std::uint64_t i = 0; i < o.count; ++i) {
    const std::uint64_t ix = i % m, iy = (i / m) % m, iz = i / (m * m);
    auto jitter = [&](unsigned stream) { return amplitude * (2 * rng.unit(i, stream) - 1); };
    const Vec3<double> p{o.offset.x + (double(ix) + 0.5) * s + jitter(kX),
                         o.offset.y + (double(iy) + 0.5) * s + jitter(kY),
                         o.offset.z + (double(iz) + 1.0) * s + jitter(kZ)};
    auto between = [&](unsigned stream) {
      return std::clamp(o.radius_low + (o.radius_high - o.radius_low) * rng.unit(i, stream), o.radius_low,
                        o.radius_high);
    };
    if (ellipsoids) {
      scene.ellipsoid_position.push_back(p);
      scene.ellipsoid_semi_axes.push_back({between(kAxisA), between(kAxisB), between(kAxisC)});
      scene.ellipsoid_orientation.push_back(random_quaternion(rng, i));
    } else {
      scene.sphere_position.push_back(p);
      scene.sphere_radius.push_back(between(kRadius));
    }
  }
  scene.radius_low = o.radius_low;
  scene.radius_high = o.radius_high;
  Attributes& a = scene.attributes;
  a["generator"] = o.kind;
  a["count"] = static_cast<std::int64_t>(o.count);
  a["seed"] = std::bit_cast<std::int64_t>(o.seed);
  a["offset_x"] = o.offset.x;
  a["offset_y"] = o.offset.y;
  a["offset_z"] = o.offset.z;
  a["pour_spacing"] = o.pour_spacing;
  // the container: an open box of the column's footprint, reaching above it, and its floor
  a["simulate_walls"] =
      fmt::format("open-box:{},{},{},{},{},{};plane:0,0,{},0,0,1", o.offset.x, o.offset.y, o.offset.z - s,
                  o.offset.x + width, o.offset.y + width, o.offset.z + 2 * height, o.offset.z);
  return scene;
}

void generate_scene_file(const std::string& path, const GenerateOptions& options, bool progress) {
  if (is_pour(options)) {
    write_scene(path, generate_pour(options));
    return;
  }
  const double edge = scene_box_edge(options);
  const BodyLaw law = body_law(options, edge);
  const std::uint64_t e = generated_ellipsoids(options), spheres = options.count - e;
  SceneFileHeader header;
  header.spheres = spheres;
  header.ellipsoids = e;
  header.radius_low = options.radius_low;
  header.radius_high = options.radius_high;
  header.attributes = generator_attributes(options, edge);
  SceneFileWriter writer(path, header);
  Progress bar("generate", "bodies", options.count, progress);
  const std::size_t block = std::min<std::size_t>(kWriteChunk, options.count);
  std::vector<Vec3<double>> position(block);
  std::vector<double> radius(spheres > 0 ? block : 0);
  for (std::uint64_t first = 0; first < spheres; first += block) {
    std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(block, spheres - first));
    for (std::size_t k = 0; k < n; ++k) law.body(first + k, position[k], radius[k]);
    writer.write_spheres(first, std::span(position).first(n), std::span(radius).first(n));
    bar.add(n);
  }
  std::vector<Vec3<double>> semi_axes(e > 0 ? block : 0);
  std::vector<std::array<double, 4>> orientation(e > 0 ? block : 0);
  for (std::uint64_t first = 0; first < e; first += block) {  // ellipsoid j is body spheres + j
    std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(block, e - first));
    for (std::size_t k = 0; k < n; ++k)
      law.ellipsoid(spheres + first + k, position[k], semi_axes[k], orientation[k]);
    writer.write_ellipsoids(first, std::span(position).first(n), std::span(semi_axes).first(n),
                            std::span(orientation).first(n));
    bar.add(n);
  }
  bar.finish();
  writer.commit();
}

}  // namespace cg
