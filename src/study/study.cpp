// `contactgrid study` (study.hpp): modes × families × backends, each timed and judged against the
// exact reference. The data flow, per family:
//   build the scene → its rounding bands → exact reference (once, at the widest band)
//   → for each mode (× tolerance) × backend: detect (timed) → compare with the reference → a row
// then the table, the CSV and the plot.
#include "study/study.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <ostream>

#include "core/ellipsoid.hpp"
#include "errors.hpp"
#include "io/text_file.hpp"
#include "reference/scene_reference.hpp"
#include "run/progress.hpp"
#include "study/study_families.hpp"
#include "timing.hpp"

namespace cg {
namespace {

// One mode × tolerance × backend run: the judged contacts (the first, untimed detect) and the median
// time of the timed ones.
struct Measured {
  std::vector<exact::FoundContact> found;
  double seconds = 0;
  std::uint64_t flagged = 0;
};

template <class Real>
std::vector<exact::FoundContact> found_contacts(const Contacts<Real>& c) {
  auto d = [](const Vec3<Real>& v) { return Vec3<double>{double(v.x), double(v.y), double(v.z)}; };
  std::vector<exact::FoundContact> out(c.size());
  for (std::size_t k = 0; k < c.size(); ++k)
    out[k] = {c.id_a[k],
              c.id_b[k],
              double(c.distance[k]),
              d(c.normal_on_b[k]),
              d(c.position_on_a[k]),
              d(c.position_on_b[k])};
  return out;
}

template <class Real>
Measured measure(const BodiesView& bodies, const EngineOptions& options, int repetitions) {
  Engine<Real> engine(options);
  const Contacts<Real> judged = engine.detect(bodies);
  Measured m{found_contacts(judged), 0, engine.stats().narrow_unconverged};
  std::vector<double> times;
  for (int r = 0; r < repetitions; ++r) {
    const auto t0 = WallClock::now();
    engine.detect(bodies);
    times.push_back(seconds_since(t0));
  }
  m.seconds = median(times);
  return m;
}

// mixed: Engine<double> with the fp32 broad phase (decisions and rows are fp64's).
Measured measure_mixed(const BodiesView& bodies, const EngineOptions& options, int repetitions) {
  EngineOptions mixed = options;
  mixed.fp32_broad_phase = true;
  return measure<double>(bodies, mixed, repetitions);
}

// A precision mode of the study: its name (--precision's), the machine epsilon of the type it decides
// contacts in (its rounding band), the ellipsoid solver's default tolerance, and how to run it.
struct StudyMode {
  const char* name;
  double epsilon;
  double default_tolerance;
  Measured (*run)(const BodiesView&, const EngineOptions&, int);
};

// The modes, one line each (a new mode is one more line).
const StudyMode kModes[] = {
    {"fp32", std::numeric_limits<float>::epsilon(), SolverSettings<float>{}.tolerance, measure<float>},
    {"mixed", std::numeric_limits<double>::epsilon(), SolverSettings<double>{}.tolerance, measure_mixed},
    {"fp64", std::numeric_limits<double>::epsilon(), SolverSettings<double>{}.tolerance, measure<double>},
};

// What the band needs of a scene: the largest local coordinate (relative to the lower corner of the
// bounding boxes) and the largest bounding radius.
struct Extent {
  double largest_local = 0, r_max = 0;
};
Extent extent_of(const BodiesView& b) {
  Vec3<double> lo{HUGE_VAL, HUGE_VAL, HUGE_VAL};
  Extent e;
  for (std::size_t i = 0; i < b.size(); ++i) {
    const Vec3<double> c = b.position[i];
    const double r = b.radius[i];
    lo = {std::min(lo.x, c.x - r), std::min(lo.y, c.y - r), std::min(lo.z, c.z - r)};
    e.r_max = std::max(e.r_max, r);
  }
  for (std::size_t i = 0; i < b.size(); ++i) {
    const Vec3<double> c = b.position[i];
    const double r = b.radius[i];
    e.largest_local = std::max({e.largest_local, c.x + r - lo.x, c.y + r - lo.y, c.z + r - lo.z});
  }
  return e;
}

// One point of the study before it runs: a mode and, for ellipsoid families, the solver tolerance
// (0: the mode's default), with its band.
struct Point {
  const StudyMode* mode;
  double tolerance;  // < 0: no ellipsoids
  double band;
};

std::vector<Point> points_of(const StudyFamily& family, const std::vector<const StudyMode*>& modes,
                             const StudyOptions& o, const Extent& e) {
  std::vector<Point> points;
  for (const StudyMode* m : modes) {
    const double rounding = 16 * m->epsilon * (e.largest_local + 2 * e.r_max);
    if (!family.ellipsoids) {
      points.push_back({m, -1, rounding});
      continue;
    }
    for (double t : o.tolerances) {
      const double used = t > 0 ? t : m->default_tolerance;
      points.push_back({m, used, rounding + used * 2 * e.r_max});
    }
  }
  return points;
}

template <class T>
std::vector<const T*> select(const std::vector<std::string>& names, const T* all, std::size_t count,
                             const char* what) {
  std::vector<const T*> out;
  for (std::size_t i = 0; i < count; ++i)
    if (names.empty() || std::find(names.begin(), names.end(), std::string(all[i].name)) != names.end())
      out.push_back(&all[i]);
  for (const std::string& n : names)
    if (std::none_of(out.begin(), out.end(), [&](const T* x) { return n == x->name; }))
      throw UsageError(fmt::format("study: unknown {} '{}'", what, n));
  return out;
}

void check_options(const StudyOptions& o) {
  if (!(o.scale > 0) || !(o.scale <= 1e4)) throw UsageError("study: --scale must be in (0, 1e4]");
  if (o.repetitions < 1) throw UsageError("study: --repetitions must be >= 1");
  if (o.tolerances.empty()) throw UsageError("study: --tolerances needs at least one value");
  for (double t : o.tolerances)
    if (!(t >= 0) || !std::isfinite(t)) throw UsageError("study: --tolerances must be finite and >= 0");
  for (Backend b : o.backends) {
    if (b == Backend::automatic) throw UsageError("study: --backends takes cpu and cuda");
    if (b == Backend::cuda && !cuda_available())
      throw UsageError("study: --backends cuda asked for, but no CUDA device is usable in this build");
  }
}

std::string number(double v) { return fmt::format("{:.3g}", v); }

void print_table(const std::vector<StudyRow>& rows, std::ostream& out) {
  out << fmt::format(
      "{:<20} {:<5} {:>7} {:<4} {:>7} {:>8} {:>10} {:>6} {:>5} {:>6} {:>5} {:>9} {:>9} {:>9} {:>9}\n",
      "family", "mode", "tol", "bknd", "bodies", "contacts", "time ms", "missed", "extra", "border", "flag",
      "pos max/r", "pos p99/r", "normal °", "dist err");
  for (const StudyRow& r : rows) {
    const std::string tol = r.tolerance < 0 ? "-" : number(r.tolerance);
    if (r.refused) {
      out << fmt::format("{:<20} {:<5} {:>7} {:<4} {:>7} refused (the engine's InputError; see stderr)\n",
                         r.family, r.mode, tol, r.backend, r.bodies);
      continue;
    }
    const exact::ContactErrors& e = r.errors;
    out << fmt::format(
        "{:<20} {:<5} {:>7} {:<4} {:>7} {:>8} {:>10.4g} {:>6} {:>5} {:>6} {:>5} {:>9} {:>9} {:>9} {:>9}\n",
        r.family, r.mode, tol, r.backend, r.bodies, r.contacts, r.seconds * 1e3, e.missed, e.extra,
        e.borderline, r.flagged, number(e.max_position_rel), number(e.p99_position_rel),
        number(e.max_normal_deg), number(e.max_distance));
  }
}

}  // namespace

std::vector<std::string> study_mode_names() {
  std::vector<std::string> names;
  for (const StudyMode& m : kModes) names.emplace_back(m.name);
  return names;
}

std::string study_csv_header() {
  return "family,mode,tolerance,backend,bodies,reference_pairs,contacts,status,time_s,repetitions,band,"
         "missed,"
         "extra,borderline,flagged,max_position_rel,p99_position_rel,max_normal_deg,max_distance_err";
}

std::string study_csv_line(const StudyRow& r) {
  const exact::ContactErrors& e = r.errors;
  return fmt::format("{},{},{},{},{},{},{},{},{:.6g},{},{:.6g},{},{},{},{},{:.6g},{:.6g},{:.6g},{:.6g}",
                     r.family, r.mode, r.tolerance < 0 ? std::string() : fmt::format("{:.6g}", r.tolerance),
                     r.backend, r.bodies, r.reference_pairs, r.contacts, r.refused ? "refused" : "ok",
                     r.seconds, r.repetitions, r.band, e.missed, e.extra, e.borderline, r.flagged,
                     e.max_position_rel, e.p99_position_rel, e.max_normal_deg, e.max_distance);
}

std::vector<StudyRow> run_study(const StudyOptions& o, std::ostream& out, std::ostream& progress) {
  check_options(o);
  const auto& all_families = study_families();
  const auto families = select(o.families, all_families.data(), all_families.size(), "family");
  const auto modes = select(o.modes, kModes, std::size(kModes), "mode");
  std::vector<Backend> backends = o.backends;
  if (backends.empty()) {
    backends.push_back(Backend::cpu);
    if (cuda_available()) backends.push_back(Backend::cuda);
  }
  progress << fmt::format(
      "study: {} families × {} modes × {} backends, scale {}, seed {}, time = median of {}\n",
      families.size(), modes.size(), backends.size(), o.scale, o.seed, o.repetitions);

  std::vector<StudyRow> rows;
  for (const StudyFamily* family : families) {
    const BodyRows scene = family->make(o.scale, o.seed);
    const BodiesView bodies = bodies_view(scene);
    const std::vector<Point> points = points_of(*family, modes, o, extent_of(bodies));
    double widest = 0;
    for (const Point& p : points) widest = std::max(widest, p.band);
    const auto t0 = WallClock::now();
    const auto reference = exact::reference_contacts(bodies, {widest, o.ellipsoid_samples});
    progress << fmt::format("  {} ({} bodies): exact reference {} pairs in {:.2f} s\n", family->name,
                            bodies.size(), reference.size(), seconds_since(t0));
    Progress bar("study: " + family->name, "runs", points.size() * backends.size());
    for (const Point& p : points)
      for (Backend b : backends) {
        StudyRow row;
        row.family = family->name;
        row.mode = p.mode->name;
        row.backend = to_string(b);
        row.tolerance = p.tolerance;
        row.bodies = bodies.size();
        row.reference_pairs = reference.size();
        row.band = p.band;
        row.repetitions = o.repetitions;
        EngineOptions eo;
        eo.backend = b;
        eo.threads = o.threads;
        eo.ellipsoid_tolerance = p.tolerance > 0 ? p.tolerance : 0;
        try {
          const Measured m = p.mode->run(bodies, eo, o.repetitions);
          row.contacts = m.found.size();
          row.flagged = m.flagged;
          row.seconds = m.seconds;
          row.errors = exact::compare_with_reference(m.found, reference, bodies.radius, p.band);
        } catch (const InputError& e) {
          row.refused = true;
          bar.finish();
          progress << fmt::format("    {} {}: refused: {}\n", row.mode, row.backend, e.what());
        }
        bar.finish();
        progress << fmt::format("    {} {}{}: {:.4g} ms, missed {}, extra {}\n", row.mode, row.backend,
                                p.tolerance < 0 ? "" : " tol " + number(p.tolerance), row.seconds * 1e3,
                                row.errors.missed, row.errors.extra)
                 << std::flush;
        rows.push_back(std::move(row));
        bar.add(1);
      }
  }

  print_table(rows, out);
  if (!o.csv.empty()) {
    std::string text = study_csv_header() + '\n';
    for (const StudyRow& r : rows) text += study_csv_line(r) + '\n';
    write_text_file(o.csv, text);
    out << "wrote " << o.csv << '\n';
  }
  if (!o.svg.empty()) {
    write_text_file(o.svg, study_svg(rows));
    out << "wrote " << o.svg << '\n';
  }
  return rows;
}

}  // namespace cg
