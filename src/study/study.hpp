#pragma once
// `contactgrid study` (issue #13): the speed/accuracy trade of the precision modes, measured. For every
// precision mode (× the ellipsoid solver tolerance on families with ellipsoids) × scene family
// (study_families.hpp) × backend present, it runs the engine on the family's scene, times it (median
// of `repetitions` detect() calls after one untimed call whose contacts are judged), and compares the
// contacts with the exact reference (src/reference: long double) within the mode's rounding band:
//
//   band = 16·ε_mode·(largest local coordinate + 2·r_max)        (docs/FORMAT.md §3; ε of the decision type)
//        + tolerance·2·r_max                                        (families with ellipsoids: the solver
//                                                                    stops at that tangential gradient)
//
// CSV columns (fixed; study_csv_header()):
//   family, mode, tolerance (ellipsoid families: the solver tolerance used; else empty), backend, bodies,
//   reference_pairs (exact distance <= the widest band run), contacts, status (ok | refused: the engine
//   refused the scene with an InputError; the message goes to stderr), time_s (median), repetitions,
//   band, missed, extra, borderline, flagged (rows the engine flagged: narrow_unconverged),
//   max_position_rel, p99_position_rel (|p − p_ref| / r), max_normal_deg, max_distance_err (length).
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "engine.hpp"
#include "reference/error_metrics.hpp"

namespace cg {

struct StudyOptions {
  double scale = 1;                   // --scale: family sizes × scale
  std::uint64_t seed = 1;             // --seed
  int repetitions = 3;                // --repetitions: timed detect() calls per point (median)
  int threads = 0;                    // --threads: CPU backend threads (0: all)
  std::vector<std::string> families;  // --families: names (empty: all)
  std::vector<std::string> modes;     // --modes: names (empty: all)
  std::vector<Backend> backends;      // --backends (empty: cpu, and cuda when available)
  std::vector<double> tolerances{0, 1e-3, 1e-6, 1e-9};  // --tolerances: 0 is the mode's default
  int ellipsoid_samples = 4000;                         // reference directions per ellipsoid pair
  std::string csv;                                      // --csv: file ("" none)
  std::string svg;                                      // --svg: the time-vs-error plot ("" none)
};

struct StudyRow {
  std::string family, mode, backend;
  double tolerance = -1;  // < 0: not an ellipsoid family
  std::uint64_t bodies = 0, reference_pairs = 0, contacts = 0, flagged = 0;
  bool refused = false;
  double seconds = 0, band = 0;
  int repetitions = 0;
  exact::ContactErrors errors;
};

// The names --modes accepts, in the study's order.
std::vector<std::string> study_mode_names();

// Runs the study: progress to `progress`, the table to `out`, the CSV and SVG when asked. Throws
// UsageError for unknown names or bad options (before anything runs), IoError when a file cannot be
// written.
std::vector<StudyRow> run_study(const StudyOptions& options, std::ostream& out, std::ostream& progress);

std::string study_csv_header();
std::string study_csv_line(const StudyRow& row);

// The plot: log time against log max position error (floored at 1e-17), one point per row, a colour
// per mode, the Pareto-optimal points (no other point of the family both faster and more accurate)
// filled and joined per family. Written by our own code (no plotting dependency).
std::string study_svg(const std::vector<StudyRow>& rows);

}  // namespace cg
