// Validation of a contact set against Bullet (see validate.hpp for the rules and the band).
//
// Data flow: check the contacts against CONTRACT §2 → index them in canonical form (id_a < id_b,
// sorted; duplicates skipped) without copying when they already are → choose the region(s): the
// whole scene, or K disjoint sub-boxes → per region: Bullet on the spheres there (ids ascending),
// the contacts of pairs inside the region, merge-join by (id_a, id_b) → aggregate → PASS/FAIL.
//
// Invariants: both lists handed to the merge are sorted by (id_a, id_b) with each pair once; every
// pair found by one side only is classified with its exact distance from the scene, never with the
// value either side computed.
#include "validate.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <utility>

#include "bullet_oracle.hpp"
#include "errors.hpp"
#include "hdf5_io.hpp"

namespace cg {
namespace {

using Key = std::pair<std::int64_t, std::int64_t>;

double norm(Vec3<double> v) { return std::sqrt(dot(v, v)); }

bool finite(Vec3<double> v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// Angle between two directions in degrees, accurate for small angles; 180 for a zero/NaN vector.
double angle_deg(Vec3<double> u, Vec3<double> v) {
  const double c = norm(cross(u, v)), d = dot(u, v);
  const double a = std::atan2(c, d) * 180.0 / 3.141592653589793;
  return std::isfinite(a) && (c != 0 || d != 0) ? a : 180.0;
}

// One contact in canonical form (A = smaller id), geometry in double.
struct Geometry {
  Vec3<double> pa, pb, n;
  double d;
};

// The contacts given, viewed in canonical order without copying their geometry.
class ContactIndex {
 public:
  explicit ContactIndex(const Contacts<double>& c) : m_c(c) {}

  // Builds the order when the rows are not already canonical and sorted; drops rows `keep` rejects.
  template <class Keep>
  void build(bool canonical_sorted, Keep keep) {
    m_order.clear();
    m_identity = canonical_sorted;
    if (canonical_sorted) {
      for (std::size_t r = 0; r < m_c.size(); ++r)
        if (!keep(r)) m_identity = false;
      if (m_identity) return;
    }
    for (std::size_t r = 0; r < m_c.size(); ++r)
      if (keep(r)) m_order.push_back(r);
    std::stable_sort(m_order.begin(), m_order.end(),
                     [&](std::size_t x, std::size_t y) { return row_key(x) < row_key(y); });
    // Each pair once: keep the first row of a run of equal keys.
    m_order.erase(std::unique(m_order.begin(), m_order.end(),
                              [&](std::size_t x, std::size_t y) { return row_key(x) == row_key(y); }),
                  m_order.end());
  }

  std::size_t size() const { return m_identity ? m_c.size() : m_order.size(); }
  std::size_t row(std::size_t k) const { return m_identity ? k : m_order[k]; }
  Key key(std::size_t k) const { return row_key(row(k)); }

  Key row_key(std::size_t r) const {
    const auto a = m_c.id_a[r], b = m_c.id_b[r];
    return a < b ? Key{a, b} : Key{b, a};
  }
  Geometry geometry(std::size_t k) const {
    const std::size_t r = row(k);
    Geometry g{m_c.position_on_a[r], m_c.position_on_b[r], m_c.normal_on_b[r], m_c.distance[r]};
    if (m_c.id_a[r] > m_c.id_b[r]) {  // the row's own A/B: express it with A = smaller id
      std::swap(g.pa, g.pb);
      g.n = -g.n;
    }
    return g;
  }
  // First k with key(k).first >= id.
  std::size_t lower_bound_a(std::int64_t id) const {
    std::size_t lo = 0, hi = size();
    while (lo < hi) {
      const std::size_t mid = lo + (hi - lo) / 2;
      if (key(mid).first < id)
        lo = mid + 1;
      else
        hi = mid;
    }
    return lo;
  }

 private:
  const Contacts<double>& m_c;
  std::vector<std::size_t> m_order;
  bool m_identity = true;
};

// Keeps the `limit` largest offenders of each kind.
class Offenders {
 public:
  explicit Offenders(std::size_t limit) : m_limit(limit) {}
  void add(const ValidateOffender& o) {
    if (m_limit == 0) return;
    auto& v = m_by_kind[std::size_t(o.kind)];
    v.push_back(o);
    if (v.size() > 4 * m_limit) trim(v);
  }
  std::vector<ValidateOffender> take() {
    std::vector<ValidateOffender> out;
    for (auto& v : m_by_kind) {
      trim(v);
      out.insert(out.end(), v.begin(), v.end());
    }
    return out;
  }

 private:
  void trim(std::vector<ValidateOffender>& v) const {
    std::stable_sort(v.begin(), v.end(),
                     [](const ValidateOffender& x, const ValidateOffender& y) { return x.value > y.value; });
    if (v.size() > m_limit) v.resize(m_limit);
  }
  std::size_t m_limit;
  std::vector<ValidateOffender> m_by_kind[5];
};

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

SceneStats scene_stats(const Scene& s) {
  SceneStats st;
  const std::size_t n = s.sphere_count();
  const double inf = std::numeric_limits<double>::infinity();
  st.centres = {{inf, inf, inf}, {-inf, -inf, -inf}};
  Box body_box = st.centres;
  double sum = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3<double> c = s.sphere_position[i];
    const double r = s.sphere_radius[i];
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

// Exact signed distance of two spheres (long double), as CONTRACT §3.
double exact_distance(const Scene& s, std::int64_t a, std::int64_t b) {
  const Vec3<double> ca = s.sphere_position[std::size_t(a)], cb = s.sphere_position[std::size_t(b)];
  const long double dx = (long double)ca.x - cb.x, dy = (long double)ca.y - cb.y,
                    dz = (long double)ca.z - cb.z;
  const long double d = std::sqrt(dx * dx + dy * dy + dz * dz);
  return double(d - ((long double)s.sphere_radius[std::size_t(a)] + s.sphere_radius[std::size_t(b)]));
}

// Compares one region: `mine` are positions in the ContactIndex (sorted by key), `ref` Bullet's.
void compare_region(const Scene& scene, const ContactIndex& index, const std::vector<std::size_t>& mine,
                    const Contacts<double>& ref, const std::vector<std::size_t>& ref_rows, double band,
                    ValidateReport& rep, Offenders& off) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::size_t i = 0, j = 0;
  auto one_sided = [&](Key k, bool only_mine, double side_distance) {
    const double ed = exact_distance(scene, k.first, k.second);
    if (std::abs(ed) <= band) {
      ++(only_mine ? rep.borderline_extra : rep.borderline_missing);
      return;
    }
    ++(only_mine ? rep.extra : rep.missing);
    off.add({only_mine ? ValidateOffender::Kind::extra : ValidateOffender::Kind::missing, k.first, k.second,
             std::abs(ed), ed, only_mine ? side_distance : nan, only_mine ? nan : side_distance});
  };
  rep.checked += mine.size();
  rep.bullet_contacts += ref_rows.size();
  while (i < mine.size() || j < ref_rows.size()) {
    const Key km = i < mine.size() ? index.key(mine[i]) : Key{INT64_MAX, INT64_MAX};
    const Key kr =
        j < ref_rows.size() ? Key{ref.id_a[ref_rows[j]], ref.id_b[ref_rows[j]]} : Key{INT64_MAX, INT64_MAX};
    if (km < kr) {
      one_sided(km, true, index.geometry(mine[i]).d);
      ++i;
    } else if (kr < km) {
      one_sided(kr, false, ref.distance[ref_rows[j]]);
      ++j;
    } else {
      const Geometry g = index.geometry(mine[i]);
      const std::size_t r = ref_rows[j];
      double pos = std::max(norm(g.pa - ref.position_on_a[r]), norm(g.pb - ref.position_on_b[r]));
      double ang = angle_deg(g.n, ref.normal_on_b[r]);
      double dist = std::abs(g.d - ref.distance[r]);
      if (!std::isfinite(pos)) pos = std::numeric_limits<double>::infinity();
      if (!std::isfinite(dist)) dist = std::numeric_limits<double>::infinity();
      ++rep.matched;
      rep.max_position_error = std::max(rep.max_position_error, pos);
      rep.max_angle_deg = std::max(rep.max_angle_deg, ang);
      rep.max_distance_error = std::max(rep.max_distance_error, dist);
      const double ed = exact_distance(scene, km.first, km.second);
      if (pos > rep.pos_eps)
        off.add({ValidateOffender::Kind::position, km.first, km.second, pos, ed, g.d, ref.distance[r]});
      if (ang > rep.angle_deg)
        off.add({ValidateOffender::Kind::angle, km.first, km.second, ang, ed, g.d, ref.distance[r]});
      if (dist > rep.band)
        off.add({ValidateOffender::Kind::distance, km.first, km.second, dist, ed, g.d, ref.distance[r]});
      ++i;
      ++j;
    }
  }
}

// Checks CONTRACT §2 on the rows as given; fills the violation counters and failure lines.
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
        "id order: {} rows have id_a > id_b (first: {}); CONTRACT §2 requires id_a < id_b, A being the "
        "body with the smaller id",
        rep.bad_id_order, row_ids(first_order)));
  if (rep.unsorted)
    rep.failures.push_back(fmt::format(
        "not sorted: {} rows come before their predecessor (first: {}); CONTRACT §2 requires rows "
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
std::vector<Box> pick_boxes(const SceneStats& st, std::size_t spheres, const ValidateOptions& o,
                            ValidateReport& rep) {
  std::vector<Box> boxes;
  if (o.sample == 0) return boxes;
  const Vec3<double> e = st.centres.hi - st.centres.lo;
  const double floor = 2 * st.r_max;  // a box thinner than a contact is meaningless
  const double ex = std::max(e.x, floor), ey = std::max(e.y, floor), ez = std::max(e.z, floor);
  const double edge =
      std::max(std::cbrt(ex * ey * ez * double(o.bodies_per_box) / double(spheres)), 4 * st.r_max);
  auto cells = [&](double span) { return std::max<std::uint64_t>(1, std::uint64_t(span / edge)); };
  const std::uint64_t mx = cells(e.x), my = cells(e.y), mz = cells(e.z);
  const std::uint64_t total = mx * my * mz;
  if (total == 1) {
    rep.notes.push_back(fmt::format("the scene ({} spheres) fits in one sub-box: checked whole", spheres));
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

}  // namespace

const char* to_string(ValidateOffender::Kind k) {
  switch (k) {
    case ValidateOffender::Kind::missing:
      return "missing";
    case ValidateOffender::Kind::extra:
      return "extra";
    case ValidateOffender::Kind::position:
      return "position";
    case ValidateOffender::Kind::angle:
      return "angle";
    case ValidateOffender::Kind::distance:
      return "distance";
  }
  return "?";
}

Precision parse_bullet_precision(const std::string& name) {
  if (name == "double" || name == "fp64") return Precision::fp64;
  if (name == "float" || name == "fp32") return Precision::fp32;
  throw UsageError("--bullet must be double or float, not '" + name + "'");
}

ValidateReport validate(const Scene& scene, const Contacts<double>& contacts, const ValidateOptions& o) {
  if (!(o.pos_eps > 0) || !std::isfinite(o.pos_eps)) throw UsageError("--pos-eps must be > 0");
  if (!(o.angle_deg > 0) || !(o.angle_deg <= 180)) throw UsageError("--angle-deg must be in (0, 180]");
  if (o.bodies_per_box < 16) throw UsageError("validate: bodies per sub-box must be >= 16");
  check_lengths(contacts);

  ValidateReport rep;
  rep.bullet = o.bullet;
  rep.pos_eps = o.pos_eps;
  rep.angle_deg = o.angle_deg;
  rep.contacts = contacts.size();

  const std::int64_t spheres = std::int64_t(scene.sphere_count());
  const std::int64_t bodies = std::int64_t(scene.size());
  const SceneStats st = scene_stats(scene);
  rep.scale = st.r_mean;
  const double bullet_tol =
      o.bullet == Precision::fp64 ? tolerance(Precision::fp64, st.r_mean, st.magnitude) : 1e-4 * st.r_mean;
  rep.band = std::max(tolerance(o.contacts_precision, st.r_mean, st.extent), bullet_tol);

  const bool canonical = check_contract(contacts, bodies, rep);
  ContactIndex index(contacts);
  index.build(canonical, [&](std::size_t r) {
    const auto a = contacts.id_a[r], b = contacts.id_b[r];
    if (a < 0 || b < 0 || a >= bodies || b >= bodies || a == b) return false;
    if (a >= spheres || b >= spheres) {
      ++rep.skipped_ellipsoid;
      return false;
    }
    return true;
  });
  if (rep.skipped_ellipsoid)
    rep.notes.push_back(
        fmt::format("{} contacts involve ellipsoids and are not checked (Bullet has no "
                    "ellipsoid shape)",
                    rep.skipped_ellipsoid));

  Offenders off(o.max_offenders);
  const std::vector<Box> boxes = pick_boxes(st, std::size_t(spheres), o, rep);
  rep.sample_boxes = boxes.size();
  if (boxes.empty()) {
    OracleSpheres all;
    all.position.assign(scene.sphere_position.begin(), scene.sphere_position.end());
    all.radius.assign(scene.sphere_radius.begin(), scene.sphere_radius.end());
    all.id.resize(std::size_t(spheres));
    std::iota(all.id.begin(), all.id.end(), std::int64_t(0));
    const OracleResult bullet = bullet_collide(all, o.bullet);
    rep.bullet_seconds += bullet.scratch_seconds;
    std::vector<std::size_t> mine(index.size()), ref(bullet.contacts.size());
    std::iota(mine.begin(), mine.end(), std::size_t(0));
    std::iota(ref.begin(), ref.end(), std::size_t(0));
    compare_region(scene, index, mine, bullet.contacts, ref, rep.band, rep, off);
  } else {
    const double margin = 2 * st.r_max;
    for (const Box& box : boxes) {
      const Box outer{box.lo - Vec3<double>{margin, margin, margin},
                      box.hi + Vec3<double>{margin, margin, margin}};
      OracleSpheres sub;
      std::vector<std::int64_t> inside;  // ids with centres inside the box itself, ascending
      for (std::int64_t i = 0; i < spheres; ++i) {
        const Vec3<double> c = scene.sphere_position[std::size_t(i)];
        if (!outer.contains(c)) continue;
        sub.position.push_back(c);
        sub.radius.push_back(scene.sphere_radius[std::size_t(i)]);
        sub.id.push_back(i);
        if (box.contains(c)) inside.push_back(i);
      }
      const OracleResult bullet = bullet_collide(sub, o.bullet);
      rep.bullet_seconds += bullet.scratch_seconds;
      auto in_box = [&](std::int64_t id) { return box.contains(scene.sphere_position[std::size_t(id)]); };
      std::vector<std::size_t> ref;
      for (std::size_t r = 0; r < bullet.contacts.size(); ++r)
        if (in_box(bullet.contacts.id_a[r]) && in_box(bullet.contacts.id_b[r])) ref.push_back(r);
      std::vector<std::size_t> mine;
      for (const std::int64_t a : inside)
        for (std::size_t k = index.lower_bound_a(a); k < index.size() && index.key(k).first == a; ++k)
          if (in_box(index.key(k).second)) mine.push_back(k);
      compare_region(scene, index, mine, bullet.contacts, ref, rep.band, rep, off);
    }
  }
  rep.offenders = off.take();

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
  if (rep.max_position_error > o.pos_eps)
    rep.failures.push_back(fmt::format("position: largest position error {:.3g} > --pos-eps {:.3g}",
                                       rep.max_position_error, o.pos_eps));
  if (rep.max_angle_deg > o.angle_deg)
    rep.failures.push_back(fmt::format("angle: largest angle between normals {:.3g}° > --angle-deg {:.3g}°",
                                       rep.max_angle_deg, o.angle_deg));
  rep.pass = rep.failures.empty();
  return rep;
}

std::string ValidateReport::text() const {
  std::string s;
  const char* flavour = bullet == Precision::fp64 ? "double" : "float";
  s += fmt::format(
      "validate: {} (Bullet {}, {})\n", pass ? "PASS" : "FAIL", flavour,
      sample_boxes ? fmt::format("{} sampled sub-boxes", sample_boxes) : std::string("whole scene"));
  s += fmt::format("  contacts: {} given, {} checked ({:.2f}% of the checkable), Bullet {}, matched {}\n",
                   contacts, checked, 100 * checked_fraction(), bullet_contacts, matched);
  s += fmt::format(
      "  only Bullet (missing): {}   only contacts (extra): {}   borderline accepted: {} + {} "
      "(band ±{:.3g}, scale {:.3g})\n",
      missing, extra, borderline_missing, borderline_extra, band, scale);
  s += fmt::format(
      "  max position error {:.3g} (limit {:.3g})   max normal angle {:.3g}° (limit {:.3g}°)   "
      "max distance error {:.3g}\n",
      max_position_error, pos_eps, max_angle_deg, angle_deg, max_distance_error);
  s += fmt::format("  Bullet time {:.3f} s\n", bullet_seconds);
  for (const auto& f : failures) s += "  FAIL " + f + "\n";
  for (const auto& n : notes) s += "  note: " + n + "\n";
  if (!offenders.empty()) {
    s += "  worst offenders:\n";
    for (const auto& o : offenders) {
      auto dist = [](double d) { return std::isnan(d) ? std::string("-") : fmt::format("{:.6g}", d); };
      s += fmt::format(
          "    {:<8} ({}, {})  value {:.4g}  exact distance {:.6g} ({})  contacts {}  Bullet {}\n",
          cg::to_string(o.kind), o.id_a, o.id_b, o.value, o.exact_distance,
          o.exact_distance <= 0 ? "contact" : "no contact", dist(o.contacts_distance),
          dist(o.bullet_distance));
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
