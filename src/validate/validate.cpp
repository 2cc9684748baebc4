// Validation of a contact set against Bullet (see validate.hpp for the rules and the band).
//
// Data flow: check the contacts against docs/FORMAT.md §2 → index them in canonical form (id_a < id_b,
// sorted; duplicates skipped) without copying when they already are → choose the region(s): the
// whole scene, or K disjoint sub-boxes → per region: Bullet on the bodies there (ids ascending; in a
// frame centred on them when the scene has ellipsoids), the contacts of pairs inside the region,
// merge-join by (id_a, id_b) (validate_compare.cpp) → aggregate → PASS/FAIL.
#include "validate/validate.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <numeric>
#include <random>
#include <utility>

#include "errors.hpp"
#include "io/contact_file.hpp"
#include "io/scene_file.hpp"
#include "io/size_text.hpp"
#include "run/progress.hpp"
#include "validate/bullet_oracle.hpp"
#include "validate/validate_detail.hpp"

namespace cg {
namespace {

using namespace validate_detail;

struct SceneStats {
  Box centres{{0, 0, 0}, {0, 0, 0}};
  double r_min = 0, r_max = 0, r_mean = 0, extent = 0, magnitude = 0;
};

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
    st.r_min = i == 0 ? r : std::min(st.r_min, r);
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

// K distinct cells, drawn at random, of a lattice over the centres' box whose cells hold about
// `per_box` centres each: disjoint by construction. Cells are half-open [lo, hi); the last cell of
// each axis is open above so every centre lies in exactly one cell. Empty: check the whole scene.
constexpr std::uint64_t kContactsPerBox = 4000;  // a sampled sub-box's pairs, about (bodies_per_box 0)

std::vector<Box> pick_boxes(const SceneStats& st, std::size_t bodies, std::uint64_t per_box,
                            const ValidateOptions& o, ValidateReport& rep) {
  std::vector<Box> boxes;
  if (o.sample == 0) return boxes;
  const Vec3<double> e = st.centres.hi - st.centres.lo;
  const double floor = 2 * st.r_max;  // a box thinner than a contact is meaningless
  const double ex = std::max(e.x, floor), ey = std::max(e.y, floor), ez = std::max(e.z, floor);
  const double edge = std::max(std::cbrt(ex * ey * ez * double(per_box) / double(bodies)), 4 * st.r_max);
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

// ---- memory ------------------------------------------------------------------------------------

// Bullet's memory, whole process, measured on random sphere and ellipsoid scenes (BENCHMARKS.md,
// "Validation at any length scale, in bounded memory"): per overlapping pair its broadphase pair, the
// collision algorithm and a btPersistentManifold of four points (double Bullet's are twice float's),
// with our copy of its contacts; per body the collision object, its shape, the broadphase proxy and
// tree nodes, and our copy of the body.
BulletCost bullet_cost(Precision bullet) {
  return bullet == Precision::fp64 ? BulletCost{2000, 1300} : BulletCost{1300, 900};
}

std::uint64_t page_bytes() { return std::uint64_t(::sysconf(_SC_PAGESIZE)); }

// This process's resident memory now (/proc/self/statm), bytes; 0 when unknown.
std::uint64_t resident_bytes() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0;
  unsigned long long size = 0, resident = 0;
  const int got = std::fscanf(f, "%llu %llu", &size, &resident);
  std::fclose(f);
  return got == 2 ? resident * page_bytes() : 0;
}

std::string bytes_text(double b) {
  if (b >= double(std::uint64_t(1) << 30))
    return fmt::format("{:.2f} GiB", b / double(std::uint64_t(1) << 30));
  if (b >= double(1 << 20)) return fmt::format("{:.0f} MiB", b / double(1 << 20));
  return fmt::format("{:.0f} KiB", b / 1024);
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
  if (rep.pos_abs && !(rep.max_position_error <= *rep.pos_abs))
    rep.failures.push_back(fmt::format("position: largest position error {:.3g} > --pos-abs {:.3g}",
                                       rep.max_position_error, *rep.pos_abs));
  if (!rep.pos_abs && !(rep.max_position_rel <= rep.pos_eps))
    rep.failures.push_back(fmt::format(
        "position: largest position error {:.3g}·L > --pos-eps {:.3g} (L: the pair's larger bounding radius)",
        rep.max_position_rel, rep.pos_eps));
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

OracleBodies oracle_bodies(const Scene& scene, const std::vector<std::int64_t>& ids, double scale,
                           double& extent) {
  OracleBodies b;
  const bool shapes = scene.ellipsoid_count() > 0;
  Box span{centre(scene, 0), centre(scene, 0)};
  if (!ids.empty()) span = {centre(scene, std::size_t(ids[0])), centre(scene, std::size_t(ids[0]))};
  b.position.reserve(ids.size());
  b.radius.reserve(ids.size());
  b.id.reserve(ids.size());
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
  b.origin = 0.5 * (span.lo + span.hi);
  b.scale = scale;
  extent = 0;
  for (std::size_t k = 0; k < b.size(); ++k) {
    const Vec3<double> c = b.position[k] - b.origin;
    extent = std::max({extent, std::abs(c.x), std::abs(c.y), std::abs(c.z)});
  }
  return b;
}

double bullet_scale(double r_mean) {
  if (!(r_mean > 0) || !std::isfinite(r_mean))
    throw Error("bullet_scale: the mean radius must be finite and > 0");
  return std::ldexp(1.0, -int(std::lround(std::log2(r_mean))));
}

double bullet_scale_of(const Scene& scene) { return bullet_scale(scene_stats(scene).r_mean); }

std::uint64_t default_memory_limit() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  const std::uint64_t four = std::uint64_t(4) << 30;
  if (pages <= 0 || page <= 0) return four;
  return std::min(four, std::uint64_t(pages) * std::uint64_t(page) / 2);
}

std::uint64_t parse_memory(const std::string& text) { return parse_size(text, "--memory"); }

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
  if (o.pos_abs && (!(*o.pos_abs > 0) || !std::isfinite(*o.pos_abs)))
    throw UsageError("--pos-abs must be > 0");
  if (!(o.angle_deg > 0) || !(o.angle_deg <= 180)) throw UsageError("--angle-deg must be in (0, 180]");
  if (!(o.shallow >= 0) || !std::isfinite(o.shallow)) throw UsageError("--shallow must be >= 0");
  if (o.shallow_abs && !(*o.shallow_abs >= 0)) throw UsageError("--shallow-abs must be >= 0");
  if (o.bodies_per_box != 0 && o.bodies_per_box < 16)
    throw UsageError("validate: bodies per sub-box must be >= 16 (or 0: automatic)");
  if (scene.size() == 0) throw InputError("validate: the scene has no bodies");
  check_lengths(contacts);

  const bool shapes = scene.ellipsoid_count() > 0;
  ValidateReport rep;
  rep.bullet = o.bullet.value_or(shapes ? Precision::fp32 : Precision::fp64);
  rep.pos_eps = o.pos_eps;
  rep.pos_abs = o.pos_abs;
  rep.angle_deg = o.angle_deg;
  rep.shallow = o.shallow;
  rep.shallow_abs = o.shallow_abs;
  rep.contacts = contacts.size();
  rep.memory_limit = o.memory_limit ? o.memory_limit : default_memory_limit();

  const std::int64_t bodies = std::int64_t(scene.size());
  const SceneStats st = scene_stats(scene);
  rep.scale = st.r_mean;
  rep.r_min = st.r_min;
  rep.r_max = st.r_max;
  rep.bullet_scale = bullet_scale(st.r_mean);
  // Float Bullet works near its origin (the middle of each piece), with the rounding of that frame.
  const double bullet_tol = rep.bullet == Precision::fp64
                                ? tolerance(Precision::fp64, st.r_mean, st.magnitude)
                                : tolerance(Precision::fp32, st.r_mean, st.extent / 2);
  rep.band = std::max(tolerance(o.contacts_precision, st.r_mean, st.extent), bullet_tol);

  const bool canonical = check_contract(contacts, bodies, rep);
  ContactIndex index(contacts);
  auto valid = [&](std::size_t r) {
    const auto a = contacts.id_a[r], b = contacts.id_b[r];
    return a >= 0 && b >= 0 && a < bodies && b < bodies && a != b;
  };
  index.build(canonical, valid);
  std::vector<std::uint32_t> degree(scene.size(), 0);  // our contacts by body: the pieces' estimates
  for (std::size_t k = 0; k < index.size(); ++k) {
    const Key key = index.key(k);
    ++degree[std::size_t(key.first)];
    ++degree[std::size_t(key.second)];
  }
  rep.notes.push_back(fmt::format(
      "Bullet's frame: lengths × {:g} (mean bounding radius {:.3g} → {:.3g}), centred on each piece; its "
      "contact breaking threshold 0.02{} {} length{} there",
      rep.bullet_scale, st.r_mean, st.r_mean * rep.bullet_scale,
      shapes ? fmt::format(" and ellipsoid margin {:g}", kEllipsoidMargin) : std::string(),
      shapes ? "are" : "is a", shapes ? "s" : ""));

  // The regions: the whole scene, or K sub-boxes; every body that may lie in a region's grown box.
  const double margin = 2 * st.r_max;
  std::vector<std::pair<Box, std::vector<std::int64_t>>> regions;
  std::uint64_t owned_total = 0;
  // Sub-boxes of 4000 bodies, or fewer where the bodies touch more: about kContactsPerBox pairs
  // owned each, so a sample costs Bullet the same at any density.
  std::uint64_t per_box = o.bodies_per_box;
  if (per_box == 0) {
    const double per_body = double(index.size()) / double(bodies);  // pairs by their id_a
    per_box = std::uint64_t(std::clamp(double(kContactsPerBox) / std::max(per_body, 1.0), 64.0, 4000.0));
  }
  const std::vector<Box> boxes = pick_boxes(st, std::size_t(bodies), per_box, o, rep);
  rep.sample_boxes = boxes.size();
  if (!boxes.empty())
    rep.notes.push_back(fmt::format("sub-boxes of about {} bodies{}", per_box,
                                    o.bodies_per_box == 0 && per_box < 4000
                                        ? fmt::format(" (about {} contacts each)", kContactsPerBox)
                                        : std::string()));
  if (boxes.empty()) {
    const double inf = std::numeric_limits<double>::infinity();
    std::vector<std::int64_t> all(static_cast<std::size_t>(bodies));
    std::iota(all.begin(), all.end(), std::int64_t(0));
    regions.push_back({Box{{-inf, -inf, -inf}, {inf, inf, inf}}, std::move(all)});
    owned_total = std::uint64_t(bodies);
  } else {
    for (const Box& box : boxes) {
      const Box outer = box.grown(margin);
      std::vector<std::int64_t> near;
      for (std::int64_t i = 0; i < bodies; ++i) {
        const Vec3<double> c = centre(scene, std::size_t(i));
        if (outer.contains(c)) near.push_back(i);
        if (box.contains(c)) ++owned_total;
      }
      regions.push_back({box, std::move(near)});
    }
  }

  // The memory left for Bullet: the limit less what this process holds now (the scene, the contacts
  // and their index, the regions) and the pieces' own lists.
  const BulletCost cost = bullet_cost(rep.bullet);
  const double held = double(resident_bytes()) + 16.0 * double(bodies);
  const double budget = o.piece_bytes ? double(o.piece_bytes) : double(rep.memory_limit) - held;
  PiecePlanner planner(scene, index, degree, margin, cost, budget);
  const double smallest = cost.per_body * 64 + cost.per_pair * 64 * 8;
  if (budget < smallest)
    throw UsageError(fmt::format(
        "--memory {}: validate already holds {} (the scene, the contacts and their index) before Bullet "
        "runs; give at least {}",
        bytes_text(double(rep.memory_limit)), bytes_text(held),
        bytes_text(held + std::max(smallest, 64.0 * (1 << 20)))));
  for (auto& [box, near] : regions) {
    planner.add_region(box, near);
    near = {};
  }

  // Bullet on a piece: its world, the bodies outside its box being partners only (never paired with
  // each other: Bullet's pairs follow the owned bodies, whatever the margin).
  std::vector<char> owned(scene.size(), 0);
  auto run_bullet = [&](const Piece& p, double& extent) {
    OracleBodies b = oracle_bodies(scene, p.world, rep.bullet_scale, extent);
    for (const std::int64_t id : p.inside) owned[std::size_t(id)] = 1;
    b.partner.resize(b.size());
    for (std::size_t k = 0; k < b.size(); ++k) b.partner[k] = owned[std::size_t(b.id[k])] ? 0 : 1;
    for (const std::int64_t id : p.inside) owned[std::size_t(id)] = 0;
    OracleResult r = bullet_collide(b, rep.bullet);
    planner.observe(p, r.pairs);
    rep.bullet_seconds += r.scratch_seconds;
    rep.child_peak_bytes = std::max(rep.child_peak_bytes, r.child_peak_bytes);
    return r;
  };

  // A probe before the whole scene: Bullet on one sub-box of a couple of thousand bodies measures its
  // pairs per body, so that the pieces fit even when the contacts given are far fewer than Bullet's.
  if (boxes.empty() && bodies > 8000) {
    ValidateOptions probe_options = o;
    probe_options.sample = 1;
    ValidateReport scratch;
    const std::vector<Box> probe = pick_boxes(st, std::size_t(bodies), 2000, probe_options, scratch);
    if (!probe.empty()) {
      Piece p{probe[0], {}, {}};
      const Box outer = probe[0].grown(margin);
      for (std::int64_t i = 0; i < bodies; ++i) {
        const Vec3<double> c = centre(scene, std::size_t(i));
        if (outer.contains(c)) p.world.push_back(i);
        if (probe[0].contains(c)) p.inside.push_back(i);
      }
      double extent = 0;
      run_bullet(p, extent);
    }
  }

  Offenders off(o.max_offenders);
  CompareContext ctx{scene, rep.band, o.contacts_precision, rep.bullet, st.magnitude, /*bullet_extent=*/0.};
  Progress progress("validate", "bodies", owned_total, o.progress);
  std::uint64_t done = 0;
  while (std::optional<Piece> piece = planner.next()) {
    const OracleResult bullet = run_bullet(*piece, ctx.bullet_extent);
    ++rep.pieces;
    rep.largest_piece = std::max<std::uint64_t>(rep.largest_piece, piece->world.size());
    rep.bullet_pairs += bullet.pairs;
    rep.largest_piece_pairs = std::max(rep.largest_piece_pairs, bullet.pairs);

    // The pairs this piece owns: id_a (the smaller id) has its centre in the piece's box.
    for (const std::int64_t id : piece->inside) owned[std::size_t(id)] = 1;
    std::vector<std::size_t> ref;
    for (std::size_t r = 0; r < bullet.contacts.size(); ++r)
      if (owned[std::size_t(bullet.contacts.id_a[r])]) ref.push_back(r);
    std::vector<std::size_t> mine;
    for (const std::int64_t a : piece->inside)
      for (std::size_t k = index.lower_bound_a(a); k < index.size() && index.key(k).first == a; ++k)
        mine.push_back(k);
    for (const std::int64_t id : piece->inside) owned[std::size_t(id)] = 0;
    compare_region(ctx, index, mine, bullet.contacts, ref, rep, off);
    done += piece->inside.size();
    progress.update(done);
  }
  progress.finish();
  rep.peak_bytes = peak_resident_bytes();  // bullet_oracle.hpp
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
  auto length = [&](const std::optional<double>& abs, double rel) {
    return abs ? fmt::format("{:.3g}", *abs)
               : fmt::format("{:g}·L (= {:.3g} … {:.3g})", rel, rel * r_min, rel * r_max);
  };
  s += fmt::format(
      "  tolerances: position {}, normal {:g}°{}; L: a pair's larger bounding radius, radii {:.3g} … "
      "{:.3g}\n",
      length(pos_abs, pos_eps), angle_deg,
      shape_matched + judged > 0
          ? fmt::format(", shallow Bullet misses below {}", length(shallow_abs, shallow))
          : std::string(),
      r_min, r_max);
  s += fmt::format("  contacts: {} given, {} checked ({:.2f}%), Bullet {}, matched {}\n", contacts, checked,
                   100 * checked_fraction(), bullet_contacts, matched);
  s += fmt::format(
      "  only Bullet (missing): {}   only contacts (extra): {}   borderline accepted: {} + {} "
      "(band ±{:.3g}, scale {:.3g})\n",
      missing, extra, borderline_missing, borderline_extra, band, scale);
  if (matched > shape_matched || shape_matched == 0)
    s += fmt::format(
        "  {}max position error {:.3g} ({:.3g}·L)   max normal angle {:.3g}°   max distance error {:.3g}\n",
        shape_matched ? "sphere pairs: " : "", max_position_error, max_position_rel, max_angle_deg,
        max_distance_error);
  if (shape_matched + judged > 0) {
    s += fmt::format(
        "  ellipsoid pairs: matched {}, agreeing {} ({:.2f}%; max position error {:.3g}·L, max normal angle "
        "{:.3g}°)\n",
        shape_matched, shape_agree,
        shape_matched ? 100.0 * double(shape_agree) / double(shape_matched) : 100.0, shape_max_position_error,
        shape_max_angle_deg);
    s += fmt::format(
        "  judged {}: our errors {}   Bullet errors {}   both valid {}   shallow Bullet misses {} (deepest "
        "{:.3g})\n",
        judged, our_errors, bullet_errors, both_valid, shallow_misses, shallow_deepest);
  }
  s += fmt::format("  Bullet: {:.3f} s, {} piece{} (largest {} bodies, {} pairs), {} pairs in all\n",
                   bullet_seconds, pieces, pieces == 1 ? "" : "s", largest_piece, largest_piece_pairs,
                   bullet_pairs);
  s += fmt::format("  memory: limit {} (--memory), peak {}{}\n", bytes_text(double(memory_limit)),
                   bytes_text(double(peak_bytes)),
                   child_peak_bytes ? fmt::format(" + float Bullet {}", bytes_text(double(child_peak_bytes)))
                                    : std::string());
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

namespace {

// Refuses a contact file that records another scene than `scene_path`: its root attribute `bodies`
// differs from the scene's body count, or its `input` names another file (neither the same file nor
// one of the same name: a scene moved since detect is accepted). Files without these attributes (not
// written by detect; bodies = 0: not recorded) are not checked.
void check_same_scene(const std::string& scene_path, std::size_t scene_bodies,
                      const std::string& contacts_path, const Attributes& attributes) {
  std::string input;
  if (auto it = attributes.find("input"); it != attributes.end())
    if (const auto* text = std::get_if<std::string>(&it->second)) input = *text;
  const std::string from = input.empty() ? std::string() : " (computed from " + input + ")";
  if (auto it = attributes.find("bodies"); it != attributes.end()) {
    if (const auto* n = std::get_if<std::int64_t>(&it->second);
        n && *n > 0 && std::uint64_t(*n) != scene_bodies)
      throw InputError(
          fmt::format("{}: these contacts are of a scene of {} bodies{}, but {} has {}: not its "
                      "contact file",
                      contacts_path, *n, from, scene_path, scene_bodies));
  }
  if (input.empty()) return;
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::equivalent(input, scene_path, ec)) return;
  if (fs::path(input).filename() == fs::path(scene_path).filename()) return;
  throw InputError(
      fmt::format("{}: these contacts were computed from {} (root attribute input), not from {}: "
                  "validate them against that scene, or run detect on this one",
                  contacts_path, input, scene_path));
}

}  // namespace

ValidateReport validate_files(const std::string& scene_path, const std::string& contacts_path,
                              ValidateOptions options) {
  const ContactFileHeader header = read_contact_header(contacts_path);
  const SceneShape shape = read_scene_shape(scene_path);
  check_same_scene(scene_path, shape.spheres + shape.ellipsoids, contacts_path, header.attributes);
  const Scene scene = read_scene(scene_path);
  const ContactFile file = read_contacts(contacts_path, /*optional_fields=*/false);
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
