// The pair-by-pair comparison of one region (validate.hpp states the rules): a merge-join of our
// contacts and Bullet's by (id_a, id_b). Sphere–sphere pairs are compared with Bullet directly;
// pairs with an ellipsoid that disagree, or that one side lacks, are settled by the judge
// (contact_judge.hpp), which decides whose answer is wrong.
//
// Invariants: both lists are sorted by (id_a, id_b) with each pair once; every pair found by one side
// only is classified with its exact distance from the scene (closed form for two spheres, the judge's
// global minimum of f otherwise), never with the value either side computed.
#include <fmt/format.h>

#include <limits>
#include <optional>

#include "validate/contact_judge.hpp"
#include "validate/validate_detail.hpp"

namespace cg::validate_detail {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double epsilon(Precision p) {
  return p == Precision::fp64 ? std::numeric_limits<double>::epsilon()
                              : double(std::numeric_limits<float>::epsilon());
}

bool is_sphere(const Scene& s, std::int64_t id) { return std::size_t(id) < s.sphere_count(); }

judge::Body body(const Scene& s, std::int64_t id) {
  const std::size_t i = std::size_t(id);
  if (i < s.sphere_count()) return judge::sphere(s.sphere_position[i], s.sphere_radius[i]);
  const std::size_t e = i - s.sphere_count();
  return judge::ellipsoid(s.ellipsoid_position[e], s.ellipsoid_semi_axes[e], s.ellipsoid_orientation[e]);
}

// Exact signed distance of two spheres (long double), as docs/FORMAT.md §3.
double sphere_distance(const Scene& s, std::int64_t a, std::int64_t b) {
  const Vec3<double> ca = s.sphere_position[std::size_t(a)], cb = s.sphere_position[std::size_t(b)];
  const long double dx = (long double)ca.x - cb.x, dy = (long double)ca.y - cb.y,
                    dz = (long double)ca.z - cb.z;
  const long double d = std::sqrt(dx * dx + dy * dy + dz * dz);
  return double(d - ((long double)s.sphere_radius[std::size_t(a)] + s.sphere_radius[std::size_t(b)]));
}

judge::Answer answer(const Geometry& g) { return {g.pa, g.pb, g.n, g.d}; }
Geometry row_geometry(const Contacts<double>& c, std::size_t r) {
  return {c.position_on_a[r], c.position_on_b[r], c.normal_on_b[r], c.distance[r]};
}

// One pair with at least one ellipsoid: its bodies, size and the judge's tolerance for each side.
class ShapePair {
 public:
  ShapePair(const CompareContext& ctx, Key k)
      : m_a(body(ctx.scene, k.first)),
        m_b(body(ctx.scene, k.second)),
        m_size(double(std::max(m_a.bounding(), m_b.bounding()))),
        m_ours_tol((ctx.contacts_precision == Precision::fp64 ? 1e-6 : 1e-4) * m_size +
                   16 * epsilon(ctx.contacts_precision) * ctx.magnitude),
        m_bullet_tol(1e-3 * m_size + 16 * epsilon(ctx.bullet_precision) * ctx.bullet_extent) {}
  double size() const { return m_size; }
  judge::Verdict ours(const Geometry& g) const { return judge_answer(m_a, m_b, answer(g), m_ours_tol); }
  judge::Verdict bullet(const Geometry& g) const { return judge_answer(m_a, m_b, answer(g), m_bullet_tol); }

 private:
  judge::Body m_a, m_b;
  double m_size, m_ours_tol, m_bullet_tol;
};

class RegionComparison {
 public:
  RegionComparison(const CompareContext& ctx, ValidateReport& rep, Offenders& off)
      : m_ctx(ctx), m_rep(rep), m_off(off) {}

  void only_ours(Key k, const Geometry& g) {
    if (both_spheres(k)) return sphere_one_sided(k, true, g.d);
    const ShapePair pair(m_ctx, k);
    const std::optional<judge::Verdict> verdict = one_sided_verdict(pair, g, /*ours=*/true);
    if (!verdict) return;
    const judge::Verdict& v = *verdict;
    if (!v.ok) {
      ++m_rep.our_errors;
      add(Kind::ours_wrong, k, std::abs(v.distance - g.d), v.distance, g.d, kNaN, "ours: " + v.reason);
    } else if (std::abs(g.d) < m_rep.shallow_limit(pair.size())) {
      ++m_rep.shallow_misses;
      m_rep.shallow_deepest = std::max(m_rep.shallow_deepest, std::abs(g.d));
      add(Kind::shallow_miss, k, std::abs(g.d), v.distance, g.d, kNaN, "Bullet missed a shallow contact");
    } else {
      ++m_rep.bullet_errors;
      add(Kind::bullet_wrong, k, std::abs(g.d), v.distance, g.d, kNaN,
          fmt::format("Bullet missed a contact {:.3g} deep (ours passes the conditions)", -g.d));
    }
  }

  void only_bullet(Key k, const Geometry& g) {
    if (both_spheres(k)) return sphere_one_sided(k, false, g.d);
    const std::optional<judge::Verdict> verdict = one_sided_verdict(ShapePair(m_ctx, k), g, /*ours=*/false);
    if (!verdict) return;
    const judge::Verdict& v = *verdict;
    if (v.distance < 0) {  // a real contact we do not report
      ++m_rep.missing;
      add(Kind::missing, k, std::abs(v.distance), v.distance, kNaN, g.d,
          v.ok ? "Bullet's answer passes the conditions" : "Bullet's answer: " + v.reason);
    } else {
      ++m_rep.bullet_errors;
      add(Kind::bullet_wrong, k, v.distance, v.distance, kNaN, g.d,
          fmt::format("Bullet invented a contact: the bodies are {:.3g} apart", v.distance));
    }
  }

  void matched(Key k, const Geometry& mine, const Geometry& ref) {
    const double pos = finite_or_inf(std::max(norm(mine.pa - ref.pa), norm(mine.pb - ref.pb)));
    const double ang = angle_deg(mine.n, ref.n);
    const double dist = finite_or_inf(std::abs(mine.d - ref.d));
    ++m_rep.matched;
    if (both_spheres(k)) return sphere_matched(k, mine, ref, pos, ang, dist);
    const ShapePair pair(m_ctx, k);
    ++m_rep.shape_matched;
    const double lim = m_rep.position_limit(pair.size());
    m_rep.shape_max_position_error = std::max(m_rep.shape_max_position_error, pos / pair.size());
    m_rep.shape_max_angle_deg = std::max(m_rep.shape_max_angle_deg, ang);
    if (pos <= lim && dist <= lim && ang <= m_rep.angle_deg) {
      ++m_rep.shape_agree;
      return;
    }
    ++m_rep.judged;
    const judge::Verdict vo = pair.ours(mine);
    const std::string differ = fmt::format("differ by {:.3g} in position, {:.3g}° in normal: ", pos, ang);
    if (!vo.ok) {
      ++m_rep.our_errors;
      add(Kind::ours_wrong, k, pos, vo.distance, mine.d, ref.d, differ + "ours: " + vo.reason);
      return;
    }
    const judge::Verdict vb = pair.bullet(ref);
    if (!vb.ok) {
      ++m_rep.bullet_errors;
      add(Kind::bullet_wrong, k, pos, vo.distance, mine.d, ref.d, differ + "Bullet's: " + vb.reason);
    } else {
      ++m_rep.both_valid;
    }
  }

 private:
  using Kind = ValidateOffender::Kind;

  static double finite_or_inf(double v) {
    return std::isfinite(v) ? v : std::numeric_limits<double>::infinity();
  }
  bool both_spheres(Key k) const {
    return is_sphere(m_ctx.scene, k.first) && is_sphere(m_ctx.scene, k.second);
  }

  // The verdict on the answer of the one side that reports a pair with an ellipsoid; nothing (and
  // counted as borderline) when the judge's exact distance lies within the band.
  std::optional<judge::Verdict> one_sided_verdict(const ShapePair& pair, const Geometry& g, bool ours) {
    ++m_rep.judged;
    judge::Verdict v = ours ? pair.ours(g) : pair.bullet(g);
    if (std::abs(v.distance) > m_ctx.band) return v;
    ++(ours ? m_rep.borderline_extra : m_rep.borderline_missing);
    return std::nullopt;
  }

  void add(Kind kind, Key k, double value, double exact, double ours, double bullet,
           std::string reason = {}) {
    m_off.add({kind, k.first, k.second, value, exact, ours, bullet, std::move(reason)});
  }

  void sphere_one_sided(Key k, bool only_mine, double side_distance) {
    const double ed = sphere_distance(m_ctx.scene, k.first, k.second);
    if (std::abs(ed) <= m_ctx.band) {
      ++(only_mine ? m_rep.borderline_extra : m_rep.borderline_missing);
      return;
    }
    ++(only_mine ? m_rep.extra : m_rep.missing);
    add(only_mine ? Kind::extra : Kind::missing, k, std::abs(ed), ed, only_mine ? side_distance : kNaN,
        only_mine ? kNaN : side_distance);
  }

  void sphere_matched(Key k, const Geometry& g, const Geometry& ref, double pos, double ang, double dist) {
    const double size = std::max(m_ctx.scene.sphere_radius[std::size_t(k.first)],
                                 m_ctx.scene.sphere_radius[std::size_t(k.second)]);
    m_rep.max_position_error = std::max(m_rep.max_position_error, pos);
    m_rep.max_position_rel = std::max(m_rep.max_position_rel, pos / size);
    m_rep.max_angle_deg = std::max(m_rep.max_angle_deg, ang);
    m_rep.max_distance_error = std::max(m_rep.max_distance_error, dist);
    const double ed = sphere_distance(m_ctx.scene, k.first, k.second);
    if (pos > m_rep.position_limit(size)) add(Kind::position, k, pos, ed, g.d, ref.d);
    if (ang > m_rep.angle_deg) add(Kind::angle, k, ang, ed, g.d, ref.d);
    if (dist > m_rep.band) add(Kind::distance, k, dist, ed, g.d, ref.d);
  }

  const CompareContext& m_ctx;
  ValidateReport& m_rep;
  Offenders& m_off;
};

}  // namespace

void compare_region(const CompareContext& ctx, const ContactIndex& index,
                    const std::vector<std::size_t>& mine, const Contacts<double>& ref,
                    const std::vector<std::size_t>& ref_rows, ValidateReport& rep, Offenders& off) {
  RegionComparison cmp(ctx, rep, off);
  rep.checked += mine.size();
  rep.bullet_contacts += ref_rows.size();
  const Key end{INT64_MAX, INT64_MAX};
  std::size_t i = 0, j = 0;
  while (i < mine.size() || j < ref_rows.size()) {
    const Key km = i < mine.size() ? index.key(mine[i]) : end;
    const Key kr = j < ref_rows.size() ? Key{ref.id_a[ref_rows[j]], ref.id_b[ref_rows[j]]} : end;
    if (km < kr) {
      cmp.only_ours(km, index.geometry(mine[i++]));
    } else if (kr < km) {
      cmp.only_bullet(kr, row_geometry(ref, ref_rows[j++]));
    } else {
      cmp.matched(km, index.geometry(mine[i++]), row_geometry(ref, ref_rows[j++]));
    }
  }
}

}  // namespace cg::validate_detail
