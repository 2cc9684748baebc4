#pragma once
// Internals of `contactgrid validate` shared by validate.cpp (regions, report) and
// validate_compare.cpp (the pair-by-pair comparison): the contacts in canonical order, the offender
// list, and the comparison of one region. Not a public header.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

#include "validate/validate.hpp"

namespace cg::validate_detail {

using Key = std::pair<std::int64_t, std::int64_t>;

// A half-open box [lo, hi) (bounds may be infinite).
struct Box {
  Vec3<double> lo, hi;
  bool contains(Vec3<double> c) const {
    return c.x >= lo.x && c.x < hi.x && c.y >= lo.y && c.y < hi.y && c.z >= lo.z && c.z < hi.z;
  }
  Box grown(double m) const { return {lo - Vec3<double>{m, m, m}, hi + Vec3<double>{m, m, m}}; }
};

inline Vec3<double> centre(const Scene& s, std::size_t id) {
  return id < s.sphere_count() ? s.sphere_position[id] : s.ellipsoid_position[id - s.sphere_count()];
}

// A sphere's radius, an ellipsoid's largest semi-axis.
inline double bounding_radius(const Scene& s, std::size_t id) {
  if (id < s.sphere_count()) return s.sphere_radius[id];
  const Vec3<double> e = s.ellipsoid_semi_axes[id - s.sphere_count()];
  return std::max({e.x, e.y, e.z});
}

// A piece of the validation (validate.hpp, "Pieces and memory"): the bodies it owns (centres in
// `box`) and its Bullet world (centres in the box grown by 2·r_max), both ids ascending.
struct Piece {
  Box box;
  std::vector<std::int64_t> inside, world;
};

inline double norm(Vec3<double> v) { return std::sqrt(dot(v, v)); }

inline bool finite(Vec3<double> v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// Angle between two directions in degrees, accurate for small angles; 180 for a zero/NaN vector.
inline double angle_deg(Vec3<double> u, Vec3<double> v) {
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
  std::vector<ValidateOffender> m_by_kind[ValidateOffender::kinds];
};

// Bullet's memory per overlapping pair and per body, whole process (measured: validate.cpp).
struct BulletCost {
  double per_pair, per_body;
};

// Cuts the regions into pieces whose Bullet world fits `budget` bytes (validate.hpp, "Pieces and
// memory"). Bullet pairs the owned bodies with every body of the world and never two margin bodies
// (OracleBodies::partner), so its pairs follow the owned bodies: the larger of pairs_per_contact ×
// our contacts with an owned body (by body: `degree`; `index` tells those between two owned bodies)
// and pairs_per_body × the owned bodies. The ratios start from measurements and follow what Bullet
// is seen to do (observe).
class PiecePlanner {
 public:
  PiecePlanner(const Scene& scene, const ContactIndex& index, const std::vector<std::uint32_t>& degree,
               double margin, BulletCost cost, double budget);
  // A region to validate: its box and every body that may lie in its grown box (ids ascending).
  void add_region(const Box& box, const std::vector<std::int64_t>& candidates);
  // The next piece whose world fits the budget (halving regions that do not); nothing when done.
  std::optional<Piece> next();
  // Bullet found `pairs` overlapping pairs in this piece's world.
  void observe(const Piece& piece, std::uint64_t pairs);
  // The bytes Bullet's world of this piece is expected to take.
  double estimate(const Piece& piece);
  double budget() const { return m_budget; }

  static constexpr std::size_t kMinPieceBodies = 32;  // never split below this many owned bodies
  // Nor run Bullet on more bodies at once: its time from scratch grows faster than N (BENCHMARKS §1:
  // slope 1.3), and a piece is the step of the progress line.
  static constexpr std::size_t kMaxPieceBodies = std::size_t(1) << 17;

 private:
  Piece make_piece(const Box& box, const std::vector<std::int64_t>& inside_of,
                   const std::vector<std::int64_t>& world_of) const;
  double contacts_of(const Piece& piece);  // our contacts with an owned body
  const Scene& m_scene;
  const ContactIndex& m_index;
  const std::vector<std::uint32_t>& m_degree;
  std::vector<char> m_owned;  // scratch marks, one per body
  double m_margin;
  BulletCost m_cost;
  double m_budget;
  double m_pairs_per_contact, m_pairs_per_body = 0;
  bool m_observed = false;       // the ratios come from Bullet, no longer from the initial guess
  std::vector<Piece> m_pending;  // a stack: the last pushed is split or run first
};

// What the comparison of a region needs besides the two contact lists.
struct CompareContext {
  const Scene& scene;
  double band;  // borderline band (validate.hpp)
  Precision contacts_precision;
  Precision bullet_precision;
  double magnitude;      // largest |world coordinate| of the scene's centres
  double bullet_extent;  // largest |centre − origin| of Bullet's frame (this piece), scene units
};

// Compares one region: `mine` are positions in the ContactIndex (sorted by key), `ref_rows` rows of
// Bullet's sorted contacts `ref`. Adds to the report's counters and maxima and to the offenders.
void compare_region(const CompareContext& ctx, const ContactIndex& index,
                    const std::vector<std::size_t>& mine, const Contacts<double>& ref,
                    const std::vector<std::size_t>& ref_rows, ValidateReport& rep, Offenders& off);

// The contacts checked against docs/FORMAT.md §2 on the rows as given (validate_contract.cpp): the
// violation counters and failure lines of `rep` filled; true when the rows are already canonical,
// sorted and unique.
bool check_contract(const Contacts<double>& c, std::int64_t bodies, ValidateReport& rep);
// InputError when the contact datasets differ in length.
void check_lengths(const Contacts<double>& c);

}  // namespace cg::validate_detail
