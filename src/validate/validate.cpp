// Validation of a contact set against Bullet (see validate.hpp for the rules and the band).
//
// Data flow: check the contacts against docs/FORMAT.md §2 → index them in canonical form (id_a < id_b,
// sorted; duplicates skipped) without copying when they already are → choose the region(s): the
// whole scene, or K disjoint sub-boxes → per region: Bullet on the bodies there (ids ascending; in a
// frame centred on them when the scene has ellipsoids), the contacts of pairs inside the region,
// merge-join by (id_a, id_b) (validate_compare.cpp) → aggregate → PASS/FAIL.
#include "validate/validate.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <utility>

#include "errors.hpp"
#include "io/contact_file.hpp"
#include "io/scene_file.hpp"
#include "validate/bullet_oracle.hpp"
#include "validate/validate_detail.hpp"

namespace cg {
namespace {

using namespace validate_detail;

struct Box {
  Vec3<double> lo, hi;
  bool contains(Vec3<double> c) const {
    return c.x >= lo.x && c.x < hi.x && c.y >= lo.y && c.y < hi.y && c.z >= lo.z && c.z < hi.z;
  }
};

struct SceneStats {
  Box centres{{0, 0, 0}, {0, 0, 0}};
  double r_max = 0, r_mean = 0, extent = 0, magnitude = 0;
};

Vec3<double> centre(const Scene& s, std::size_t id) {
  return id < s.sphere_count() ? s.sphere_position[id] : s.ellipsoid_position[id - s.sphere_count()];
}

// A sphere's radius, an ellipsoid's largest semi-axis.
double bounding_radius(const Scene& s, std::size_t id) {
  if (id < s.sphere_count()) return s.sphere_radius[id];
  const Vec3<double> e = s.ellipsoid_semi_axes[id - s.sphere_count()];
  return std::max({e.x, e.y, e.z});
}

SceneStats scene_stats(const Scene& s) {
  SceneStats st;
  const std::size_t n = s.size();
  const double inf = std::numeric_limits<double>::infinity();
  st.centres = {{inf, inf, inf}, {-inf, -inf, -inf}};
  Box body_box = st.centres;
  double sum = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3<double> c = centre(s, i);
    const double r = bounding_radius(s, i);
    st.centres.lo = {std::min(st.centres.lo.x, c.x), std::min(st.centres.lo.y, c.y),
                     std::min(st.centres.lo.z, c.z)};
    st.centres.hi = {std::max(st.centres.hi.x, c.x), std::max(st.centres.hi.y, c.y),
                     std::max(st.centres.hi.z, c.z)};
    body_box.lo = {std::min(body_box.lo.x, c.x - r), std::min(body_box.lo.y, c.y - r),
                   std::min(body_box.lo.z, c.z - r)};
    body_box.hi = {std::max(body_box.hi.x, c.x + r), std::max(body_box.hi.y, c.y + r),
                   std::max(body_box.hi.z, c.z + r)};
    st.r_max = std::max(st.r_max, r);
    sum += r;
    st.magnitude = std::max({st.magnitude, std::abs(c.x), std::abs(c.y), std::abs(c.z)});
  }
  if (n) {
    st.r_mean = sum / double(n);
    const Vec3<double> e = body_box.hi - body_box.lo;
    st.extent = std::max({e.x, e.y, e.z});
  }
  return st;
}

double tolerance(Precision p, double scale, double span) {
  return p == Precision::fp64
             ? std::max(1e-9 * scale, 16 * std::numeric_limits<double>::epsilon() * span)
             : std::max(1e-4 * scale, 16 * double(std::numeric_limits<float>::epsilon()) * span);
}

// Checks docs/FORMAT.md §2 on the rows as given; fills the violation counters and failure lines.
// Returns true when the rows are already canonical, sorted and unique.
bool check_contract(const Contacts<double>& c, std::int64_t bodies, ValidateReport& rep) {
  std::int64_t first_order = -1, first_unsorted = -1, first_dup = -1, first_bad = -1, first_nf = -1;
  for (std::size_t r = 0; r < c.size(); ++r) {
    const auto a = c.id_a[r], b = c.id_b[r];
    if (a < 0 || b < 0 || a >= bodies || b >= bodies || a == b) {
      if (rep.bad_ids++ == 0) first_bad = std::int64_t(r);
      continue;
    }
    if (a > b && rep.bad_id_order++ == 0) first_order = std::int64_t(r);
    if (r > 0) {  // on canonical keys, so one swapped row is one id-order failure, nothing else
      const auto pa = c.id_a[r - 1], pb = c.id_b[r - 1];
      const Key prev{std::min(pa, pb), std::max(pa, pb)}, cur{std::min(a, b), std::max(a, b)};
      if (cur < prev && rep.unsorted++ == 0) first_unsorted = std::int64_t(r);
      if (cur == prev && rep.duplicates++ == 0) first_dup = std::int64_t(r);
    }
    if ((!finite(c.position_on_a[r]) || !finite(c.position_on_b[r]) || !finite(c.normal_on_b[r]) ||
         !std::isfinite(c.distance[r])) &&
        rep.non_finite++ == 0)
      first_nf = std::int64_t(r);
  }
  auto row_ids = [&](std::int64_t r) {
    return fmt::format("row {}, ids ({}, {})", r, c.id_a[std::size_t(r)], c.id_b[std::size_t(r)]);
  };
  if (rep.bad_ids)
    rep.failures.push_back(fmt::format(
        "{} rows name ids outside 0 … {} or the same body twice (first: {}); they are not compared",
        rep.bad_ids, bodies - 1, row_ids(first_bad)));
  if (rep.bad_id_order)
    rep.failures.push_back(fmt::format(
        "id order: {} rows have id_a > id_b (first: {}); docs/FORMAT.md §2 requires id_a < id_b, A being the "
        "body with the smaller id",
        rep.bad_id_order, row_ids(first_order)));
  if (rep.unsorted)
    rep.failures.push_back(fmt::format(
        "not sorted: {} rows come before their predecessor (first: {}); docs/FORMAT.md §2 requires rows "
        "sorted by (id_a, id_b)",
        rep.unsorted, row_ids(first_unsorted)));
  if (rep.duplicates)
    rep.failures.push_back(fmt::format(
        "duplicates: {} rows repeat the pair of the row before (first: {}); each pair must appear once",
        rep.duplicates, row_ids(first_dup)));
  if (rep.non_finite)
    rep.failures.push_back(
        fmt::format("{} rows hold non-finite values (first: {})", rep.non_finite, row_ids(first_nf)));
  return rep.bad_ids == 0 && rep.bad_id_order == 0 && rep.unsorted == 0 && rep.duplicates == 0;
}

void check_lengths(const Contacts<double>& c) {
  const std::size_t k = c.id_a.size();
  if (c.id_b.size() != k || c.position_on_a.size() != k || c.position_on_b.size() != k ||
      c.normal_on_b.size() != k || c.distance.size() != k)
    throw InputError("validate: the contact datasets have different lengths");
}

// K distinct cells, drawn at random, of a lattice over the centres' box whose cells hold about
// `per_box` centres each: disjoint by construction. Cells are half-open [lo, hi); the last cell of
// each axis is open above so every centre lies in exactly one cell. Empty: check the whole scene.
std::vector<Box> pick_boxes(const SceneStats& st, std::size_t bodies, const ValidateOptions& o,
                            ValidateReport& rep) {
  std::vector<Box> boxes;
  if (o.sample == 0) return boxes;
  const Vec3<double> e = st.centres.hi - st.centres.lo;
  const double floor = 2 * st.r_max;  // a box thinner than a contact is meaningless
  const double ex = std::max(e.x, floor), ey = std::max(e.y, floor), ez = std::max(e.z, floor);
  const double edge =
      std::max(std::cbrt(ex * ey * ez * double(o.bodies_per_box) / double(bodies)), 4 * st.r_max);
  auto cells = [&](double span) { return std::max<std::uint64_t>(1, std::uint64_t(span / edge)); };
  const std::uint64_t mx = cells(e.x), my = cells(e.y), mz = cells(e.z);
  const std::uint64_t total = mx * my * mz;
  if (total == 1) {
    rep.notes.push_back(fmt::format("the scene ({} bodies) fits in one sub-box: checked whole", bodies));
    return boxes;
  }
  std::mt19937_64 rng(o.seed);
  std::vector<std::uint64_t> chosen;
  if (o.sample >= total) {
    chosen.resize(total);
    std::iota(chosen.begin(), chosen.end(), std::uint64_t(0));
    rep.notes.push_back(fmt::format("only {} sub-boxes exist (asked {}): all are checked", total, o.sample));
  } else {  // K distinct cells (Floyd's algorithm: exact, no full shuffle)
    std::vector<std::uint64_t> set;
    for (std::uint64_t j = total - o.sample; j < total; ++j) {
      const std::uint64_t t = std::uniform_int_distribution<std::uint64_t>(0, j)(rng);
      set.push_back(std::find(set.begin(), set.end(), t) == set.end() ? t : j);
    }
    chosen = set;
    std::sort(chosen.begin(), chosen.end());
  }
  const double inf = std::numeric_limits<double>::infinity();
  auto range = [&](double lo, double span, std::uint64_t m, std::uint64_t i) {
    const double w = span / double(m);
    return std::pair{lo + w * double(i), i + 1 == m ? inf : lo + w * double(i + 1)};
  };
  for (const std::uint64_t c : chosen) {
    const auto [x0, x1] = range(st.centres.lo.x, e.x, mx, c % mx);
    const auto [y0, y1] = range(st.centres.lo.y, e.y, my, (c / mx) % my);
    const auto [z0, z1] = range(st.centres.lo.z, e.z, mz, c / (mx * my));
    boxes.push_back({{x0, y0, z0}, {x1, y1, z1}});
  }
  return boxes;
}

// The failure lines of the report's counters (contract violations were added by check_contract).
void add_failures(ValidateReport& rep) {
  if (rep.missing)
    rep.failures.push_back(
        fmt::format("missing: {} pairs Bullet found are not in the contacts (outside "
                    "the borderline band ±{:.3g})",
                    rep.missing, rep.band));
  if (rep.extra)
    rep.failures.push_back(
        fmt::format("extra: {} pairs in the contacts Bullet did not find (outside the "
                    "borderline band ±{:.3g})",
                    rep.extra, rep.band));
  if (rep.max_position_error > rep.pos_eps)
    rep.failures.push_back(fmt::format("position: largest position error {:.3g} > --pos-eps {:.3g}",
                                       rep.max_position_error, rep.pos_eps));
  if (rep.max_angle_deg > rep.angle_deg)
    rep.failures.push_back(fmt::format("angle: largest angle between normals {:.3g}° > --angle-deg {:.3g}°",
                                       rep.max_angle_deg, rep.angle_deg));
  if (rep.our_errors) {
    auto first = std::find_if(rep.offenders.begin(), rep.offenders.end(), [](const ValidateOffender& o) {
      return o.kind == ValidateOffender::Kind::ours_wrong;
    });
    const std::string worst =
        first == rep.offenders.end()
            ? std::string()
            : fmt::format(" (worst: ({}, {}): {})", first->id_a, first->id_b, first->reason);
    rep.failures.push_back(
        fmt::format("judged wrong: {} of our ellipsoid contacts fail the optimality conditions{}",
                    rep.our_errors, worst));
  }
}

}  // namespace

OracleBodies oracle_bodies(const Scene& scene, const std::vector<std::int64_t>& ids, bool framed,
                           double& extent) {
  OracleBodies b;
  const bool shapes = scene.ellipsoid_count() > 0;
  Box span{centre(scene, 0), centre(scene, 0)};
  for (const std::int64_t id : ids) {
    const std::size_t i = std::size_t(id);
    const Vec3<double> c = centre(scene, i);
    b.position.push_back(c);
    b.radius.push_back(bounding_radius(scene, i));
    b.id.push_back(id);
    if (shapes) {
      const bool sphere = i < scene.sphere_count();
      const std::size_t e = i - scene.sphere_count();
      b.semi_axes.push_back(sphere ? Vec3<double>{0, 0, 0} : scene.ellipsoid_semi_axes[e]);
      b.orientation.push_back(sphere ? std::array<double, 4>{1, 0, 0, 0} : scene.ellipsoid_orientation[e]);
    }
    span.lo = {std::min(span.lo.x, c.x), std::min(span.lo.y, c.y), std::min(span.lo.z, c.z)};
    span.hi = {std::max(span.hi.x, c.x), std::max(span.hi.y, c.y), std::max(span.hi.z, c.z)};
  }
  if (framed && !ids.empty()) b.origin = 0.5 * (span.lo + span.hi);
  extent = 0;
  for (std::size_t k = 0; k < b.size(); ++k) {
    const Vec3<double> c = b.position[k] - b.origin;
    extent = std::max({extent, std::abs(c.x), std::abs(c.y), std::abs(c.z)});
  }
  return b;
}

const char* to_string(ValidateOffender::Kind k) {
  static constexpr const char* names[ValidateOffender::kinds] = {
      "missing",  "extra",      "position",     "angle",
      "distance", "ours wrong", "Bullet wrong", "shallow Bullet miss"};
  return std::size_t(k) < ValidateOffender::kinds ? names[std::size_t(k)] : "?";
}

std::optional<Precision> parse_bullet_precision(const std::string& name) {
  if (name == "double" || name == "fp64") return Precision::fp64;
  if (name == "float" || name == "fp32") return Precision::fp32;
  if (name == "auto") return std::nullopt;
  throw UsageError("--bullet-precision must be auto, double or float, not '" + name + "'");
}

ValidateReport validate(const Scene& scene, const Contacts<double>& contacts, const ValidateOptions& o) {
  if (!(o.pos_eps > 0) || !std::isfinite(o.pos_eps)) throw UsageError("--pos-eps must be > 0");
  if (!(o.angle_deg > 0) || !(o.angle_deg <= 180)) throw UsageError("--angle-deg must be in (0, 180]");
  if (!(o.shallow_threshold >= 0)) throw UsageError("--shallow must be >= 0");
  if (o.bodies_per_box < 16) throw UsageError("validate: bodies per sub-box must be >= 16");
  check_lengths(contacts);

  const bool shapes = scene.ellipsoid_count() > 0;
  ValidateReport rep;
  rep.bullet = o.bullet.value_or(shapes ? Precision::fp32 : Precision::fp64);
  rep.pos_eps = o.pos_eps;
  rep.angle_deg = o.angle_deg;
  rep.shallow_threshold = o.shallow_threshold;
  rep.contacts = contacts.size();

  const std::int64_t bodies = std::int64_t(scene.size());
  const SceneStats st = scene_stats(scene);
  rep.scale = st.r_mean;
  const double bullet_tol =
      rep.bullet == Precision::fp64 ? tolerance(Precision::fp64, st.r_mean, st.magnitude) : 1e-4 * st.r_mean;
  rep.band = std::max(tolerance(o.contacts_precision, st.r_mean, st.extent), bullet_tol);

  const bool canonical = check_contract(contacts, bodies, rep);
  ContactIndex index(contacts);
  index.build(canonical, [&](std::size_t r) {
    const auto a = contacts.id_a[r], b = contacts.id_b[r];
    return a >= 0 && b >= 0 && a < bodies && b < bodies && a != b;
  });
  if (shapes)
    rep.notes.push_back(fmt::format(
        "ellipsoids: Bullet shape with the exact support and margin {:g}; Bullet works in a frame centred on "
        "the bodies of each region; shallow Bullet misses: |distance| < {:.3g}",
        kEllipsoidMargin, o.shallow_threshold));

  Offenders off(o.max_offenders);
  CompareContext ctx{scene,         rep.band,           o.contacts_precision, rep.bullet, st.magnitude,
                     /*extent=*/0., o.shallow_threshold};
  const std::vector<Box> boxes = pick_boxes(st, std::size_t(bodies), o, rep);
  rep.sample_boxes = boxes.size();
  if (boxes.empty()) {
    std::vector<std::int64_t> all(static_cast<std::size_t>(bodies));
    std::iota(all.begin(), all.end(), std::int64_t(0));
    const OracleResult bullet =
        bullet_collide(oracle_bodies(scene, all, shapes, ctx.bullet_extent), rep.bullet);
    rep.bullet_seconds += bullet.scratch_seconds;
    std::vector<std::size_t> mine(index.size()), ref(bullet.contacts.size());
    std::iota(mine.begin(), mine.end(), std::size_t(0));
    std::iota(ref.begin(), ref.end(), std::size_t(0));
    compare_region(ctx, index, mine, bullet.contacts, ref, rep, off);
  } else {
    const double margin = 2 * st.r_max;
    for (const Box& box : boxes) {
      const Box outer{box.lo - Vec3<double>{margin, margin, margin},
                      box.hi + Vec3<double>{margin, margin, margin}};
      std::vector<std::int64_t> near, inside;  // centres inside the grown box / the box itself, ascending
      for (std::int64_t i = 0; i < bodies; ++i) {
        const Vec3<double> c = centre(scene, std::size_t(i));
        if (outer.contains(c)) near.push_back(i);
        if (box.contains(c)) inside.push_back(i);
      }
      const OracleResult bullet =
          bullet_collide(oracle_bodies(scene, near, shapes, ctx.bullet_extent), rep.bullet);
      rep.bullet_seconds += bullet.scratch_seconds;
      auto in_box = [&](std::int64_t id) { return box.contains(centre(scene, std::size_t(id))); };
      std::vector<std::size_t> ref;
      for (std::size_t r = 0; r < bullet.contacts.size(); ++r)
        if (in_box(bullet.contacts.id_a[r]) && in_box(bullet.contacts.id_b[r])) ref.push_back(r);
      std::vector<std::size_t> mine;
      for (const std::int64_t a : inside)
        for (std::size_t k = index.lower_bound_a(a); k < index.size() && index.key(k).first == a; ++k)
          if (in_box(index.key(k).second)) mine.push_back(k);
      compare_region(ctx, index, mine, bullet.contacts, ref, rep, off);
    }
  }
  rep.offenders = off.take();
  add_failures(rep);
  rep.pass = rep.failures.empty();
  return rep;
}

std::string ValidateReport::text() const {
  std::string s;
  const char* flavour = bullet == Precision::fp64 ? "double" : "float";
  s += fmt::format(
      "validate: {} (Bullet {}, {})\n", pass ? "PASS" : "FAIL", flavour,
      sample_boxes ? fmt::format("{} sampled sub-boxes", sample_boxes) : std::string("whole scene"));
  s += fmt::format("  contacts: {} given, {} checked ({:.2f}%), Bullet {}, matched {}\n", contacts, checked,
                   100 * checked_fraction(), bullet_contacts, matched);
  s += fmt::format(
      "  only Bullet (missing): {}   only contacts (extra): {}   borderline accepted: {} + {} "
      "(band ±{:.3g}, scale {:.3g})\n",
      missing, extra, borderline_missing, borderline_extra, band, scale);
  if (matched > shape_matched || shape_matched == 0)
    s += fmt::format(
        "  {}max position error {:.3g} (limit {:.3g})   max normal angle {:.3g}° (limit {:.3g}°)   "
        "max distance error {:.3g}\n",
        shape_matched ? "sphere pairs: " : "", max_position_error, pos_eps, max_angle_deg, angle_deg,
        max_distance_error);
  if (shape_matched + judged > 0) {
    s += fmt::format(
        "  ellipsoid pairs: matched {}, agreeing {} ({:.2f}%; max position error {:.3g}·L, max normal angle "
        "{:.3g}°)\n",
        shape_matched, shape_agree,
        shape_matched ? 100.0 * double(shape_agree) / double(shape_matched) : 100.0, shape_max_position_error,
        shape_max_angle_deg);
    s += fmt::format(
        "  judged {}: our errors {}   Bullet errors {}   both valid {}   shallow Bullet misses {} "
        "(|distance| < "
        "{:.3g}, deepest {:.3g})\n",
        judged, our_errors, bullet_errors, both_valid, shallow_misses, shallow_threshold, shallow_deepest);
  }
  s += fmt::format("  Bullet time {:.3f} s\n", bullet_seconds);
  for (const auto& f : failures) s += "  FAIL " + f + "\n";
  for (const auto& n : notes) s += "  note: " + n + "\n";
  if (!offenders.empty()) {
    s += "  worst offenders:\n";
    for (const auto& o : offenders) {
      auto dist = [](double d) { return std::isnan(d) ? std::string("-") : fmt::format("{:.6g}", d); };
      s += fmt::format(
          "    {:<8} ({}, {})  value {:.4g}  exact distance {:.6g} ({})  contacts {}  Bullet {}{}\n",
          cg::to_string(o.kind), o.id_a, o.id_b, o.value, o.exact_distance,
          o.exact_distance <= 0 ? "contact" : "no contact", dist(o.contacts_distance),
          dist(o.bullet_distance), o.reason.empty() ? std::string() : "\n      " + o.reason);
    }
  }
  return s;
}

ValidateReport validate_files(const std::string& scene_path, const std::string& contacts_path,
                              ValidateOptions options) {
  const Scene scene = read_scene(scene_path);
  const ContactFile file = read_contacts(contacts_path);
  if (file.precision == "fp32")
    options.contacts_precision = Precision::fp32;
  else if (file.precision == "fp64" || file.precision == "mixed" || file.precision.empty())
    options.contacts_precision = Precision::fp64;
  else
    throw InputError(contacts_path + ": unknown precision attribute '" + file.precision + "'");
  ValidateReport rep = validate(scene, file.contacts, options);
  rep.notes.insert(rep.notes.begin(), "scene " + scene_path + ", contacts " + contacts_path + " (" +
                                          std::string(file.precision.empty() ? "fp64" : file.precision) +
                                          ")");
  return rep;
}

}  // namespace cg
