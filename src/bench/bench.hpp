#pragma once
// `contactgrid bench`: the timing study (course report Figures 1–2). For N = 2^lo … 2^max(bullet_hi,
// engine_hi) it generates a scene of the chosen kind (generate_scene, seeded), times Bullet from
// scratch while N <= 2^bullet_hi, and the engine (--precision: fp64 by default) on each backend
// while N <= 2^engine_hi; prints a table, writes a CSV, and (spheres) plots it with jobs/plot_bench.gp.
//
// Kinds (--kind):
//   spheres     `generate --kind uniform` (radii U[radius_low, radius_high]); Bullet = DOUBLE Bullet
//               (btSphereShape, world coordinates), from scratch and for one warm step.
//   ellipsoids  `generate --kind ellipsoids` with semi-axes U[radius_high / max_aspect, radius_high]
//               (so no body is more elongated than 1 : max_aspect; issue #12's scene: 4), uniform
//               orientations; Bullet = FLOAT Bullet (contactgrid-bullet-float) with the exact-support
//               ellipsoid (bullet_ellipsoid_shape.hpp, margin kEllipsoidMargin), relative to the middle
//               of the centres' box as `validate` runs it, from scratch only.
//   mixed       `generate --kind mixed`: round(ellipsoid_fraction · N) ellipsoids as above, the rest
//               spheres with radii from the same U[radius_high / max_aspect, radius_high]; float Bullet.
//
// Engine timing: one Engine per backend and N, one untimed warm-up detect(), then the median of
// `repetitions` timed detect() calls (wall clock around the call, host results included); the
// narrow stage's time is the median of its StageTimes entry over the same calls.
// Bullet timing: bullet_collide(): scratch = world construction + adding the bodies + first
// detection; warm (spheres only) = move every body by 1e-3·r + detect again.
// "agree": spheres: every contact count measured at that N (engine backends, Bullet) is the same.
// Ellipsoids and mixed: the engine backends' counts are the same and Bullet's differs from them by
// at most bullet_count_allowance() (float Bullet misses 0.2–0.3 % of the contacts, all shallow:
// docs/VALIDATION.md, BENCHMARKS.md §8).
//
// CSV columns, spheres (fixed; an empty field means "not run"):
//   n, log2n, contacts, bullet_contacts, agree, bullet_scratch_s, bullet_warm_s, engine_cpu_s,
//   engine_cuda_s, speedup_cpu_vs_scratch, speedup_cpu_vs_warm, speedup_cuda_vs_scratch,
//   speedup_cuda_vs_warm
// CSV columns, ellipsoids and mixed (kShapeCsvColumns; speedup = Bullet time / engine time):
//   n, log2n, kind, ellipsoids, contacts, bullet_contacts, agree, bullet_scratch_s, engine_cpu_s,
//   engine_cuda_s, speedup_cpu_vs_scratch, speedup_cuda_vs_scratch, candidates, narrow_hard,
//   narrow_fallbacks, narrow_unconverged, narrow_cpu_s, narrow_cuda_s, narrow_cpu_pairs_per_s,
//   narrow_cuda_pairs_per_s
// (the EngineStats counters of the first backend run; candidates = pairs the narrow phase decided,
// narrow_hard = those whose first start was not certified global so the whole start set ran;
// pairs_per_s = candidates / the narrow stage's time).
// Fitted slopes: least squares of log(time) on log(N) over the rows with N >= 2^14 (slope 1 = linear).
#include <cstdint>
#include <iosfwd>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include "engine.hpp"

namespace cg {

enum class BenchKind { spheres, ellipsoids, mixed };
const char* to_string(BenchKind kind);

inline constexpr const char* kShapeCsvColumns =
    "n,log2n,kind,ellipsoids,contacts,bullet_contacts,agree,bullet_scratch_s,engine_cpu_s,engine_cuda_s,"
    "speedup_cpu_vs_scratch,speedup_cuda_vs_scratch,candidates,narrow_hard,narrow_fallbacks,"
    "narrow_unconverged,narrow_cpu_s,narrow_cuda_s,narrow_cpu_pairs_per_s,narrow_cuda_pairs_per_s";

// Float Bullet (exact ellipsoid support, margin 0.04) misses this share of the contacts, all shallow
// (|distance| < 0.004): 0.2–0.3 % at semi-axes U[0.5, 1] (BENCHMARKS.md §8), 0.36 % and 0.49 % at
// U[0.25, 1] (bench's scenes at 2^14 and 2^16: 11 of 3 061, 59 of 11 974, judged by `validate`). The
// largest |engine − Bullet| contact count difference that still "agrees" on a scene with ellipsoids:
// the expected misses μ = rate × the engine's count plus three Poisson deviations, ceil(μ + 3√μ), and
// at least 3.
inline constexpr double kBulletShallowMissRate = 0.005;
std::int64_t bullet_count_allowance(std::int64_t engine_contacts);

struct BenchOptions {
  BenchKind kind = BenchKind::spheres;    // --kind spheres | ellipsoids | mixed
  double max_aspect = 4;                  // --max-aspect: ellipsoids, mixed: semi-axes U[r_high / K, r_high]
  double ellipsoid_fraction = 0.5;        // --ellipsoid-fraction: mixed
  int lo = 10;                            // --lo: first N = 2^lo
  int bullet_hi = 20;                     // --bullet-hi: Bullet runs while N <= 2^bullet_hi (< lo: never)
  int engine_hi = 22;                     // --engine-hi: engine runs while N <= 2^engine_hi
  int repetitions = 5;                    // --repetitions: engine timings are the median of this many
  std::vector<Backend> backends;          // --backend cpu|cuda (repeatable); empty: cpu, + cuda if available
  int threads = 0;                        // --threads: CPU backend threads (0: all)
  Precision precision = Precision::fp64;  // --precision fp32 | fp64 | mixed: the engine's mode
  std::uint64_t seed = 1;                 // --seed: scene generator seed (scene i uses seed + log2 N)
  double radius_low = 0.5, radius_high = 1.0;  // spheres: radii U[radius_low, radius_high]
  double contacts_per_body = 0.4;              // --contacts-per-body: generate's (bounding-sphere) density
  std::string csv = "bench.csv";               // --csv
  bool plot = true;                            // --no-plot turns it off
  std::string plot_prefix;                     // --plot-prefix: PNG/SVG names; default: csv without ".csv"
  std::string plot_script;                     // --plot-script; default: see bench_plot_script()
};

// The narrow phase of one engine run (scenes with ellipsoids).
struct NarrowCounters {
  std::uint64_t candidates = 0, narrow_hard = 0, narrow_fallbacks = 0, narrow_unconverged = 0;
  double narrow_s = -1;  // median narrow-stage seconds
};

struct BenchRow {
  std::uint64_t n = 0;
  std::uint64_t ellipsoids = 0;
  std::int64_t contacts = -1;         // engine (first backend run); -1: not run
  std::int64_t bullet_contacts = -1;  // -1: Bullet not run
  double bullet_scratch_s = -1, bullet_warm_s = -1;
  std::map<Backend, double> engine_s;  // median seconds per backend run
  std::map<Backend, std::int64_t> engine_contacts;
  std::map<Backend, NarrowCounters> narrow;  // per backend run
  bool compared = false, agree = false;      // compared: at least two counts were measured
};

struct BenchResult {
  std::vector<BenchRow> rows;
  std::map<std::string, double> slopes;  // "bullet_scratch", "bullet_warm", "engine_cpu", "engine_cuda"
  std::string csv_path;
  bool plotted = false;
};

// Runs the study, printing progress and the table to `out`. Throws UsageError for bad options,
// IoError when the CSV cannot be written. A failing gnuplot is reported, not thrown.
BenchResult run_bench(const BenchOptions& options, std::ostream& out = std::cout);

// Least-squares slope of log(y) against log(x) over the points with x >= x_min and y > 0;
// NaN with fewer than two points.
double loglog_slope(const std::vector<double>& x, const std::vector<double>& y, double x_min);

// The gnuplot script: options.plot_script if set, else $CONTACTGRID_PLOT_SCRIPT, else
// <dir of the executable>/../share/contactgrid/plot_bench.gp, else jobs/plot_bench.gp of the source
// tree this was built from. "" when none exists.
std::string bench_plot_script(const BenchOptions& options);

}  // namespace cg
