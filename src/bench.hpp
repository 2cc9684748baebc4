#pragma once
// `contactgrid bench`: the timing study (course report Figures 1–2). For N = 2^lo … 2^max(bullet_hi,
// engine_hi) it generates a uniform scene (generate_scene, seeded), times Bullet double from scratch
// and for one warm step while N <= 2^bullet_hi, and the engine (--precision: fp64 by default) on each backend
// while N <= 2^engine_hi; prints a table, writes a CSV, and plots it with jobs/plot_bench.gp.
//
// Engine timing: one Engine per backend and N, one untimed warm-up detect(), then the median of
// `repetitions` timed detect() calls (wall clock around the call, host results included).
// Bullet timing: bullet_collide(…, fp64, warm_step = true): scratch = world construction + adding the
// bodies + first detection; warm = move every body by 1e-3·r + detect again.
// "agree": every contact count measured at that N (engine backends, Bullet) is the same.
//
// CSV columns (fixed; an empty field means "not run"):
//   n, log2n, contacts, bullet_contacts, agree, bullet_scratch_s, bullet_warm_s, engine_cpu_s,
//   engine_cuda_s, speedup_cpu_vs_scratch, speedup_cpu_vs_warm, speedup_cuda_vs_scratch,
//   speedup_cuda_vs_warm
// Fitted slopes: least squares of log(time) on log(N) over the rows with N >= 2^14 (slope 1 = linear).
#include <cstdint>
#include <iosfwd>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include "engine.hpp"

namespace cg {

struct BenchOptions {
  int lo = 10;                    // --lo: first N = 2^lo
  int bullet_hi = 20;             // --bullet-hi: Bullet runs while N <= 2^bullet_hi (< lo: never)
  int engine_hi = 22;             // --engine-hi: engine runs while N <= 2^engine_hi
  int repetitions = 5;            // --repetitions: engine timings are the median of this many
  std::vector<Backend> backends;  // --backend cpu|cuda (repeatable); empty: cpu, + cuda if available
  int threads = 0;                // --threads: CPU backend threads (0: all)
  Precision precision = Precision::fp64;  // --precision fp32 | fp64 | mixed: the engine's mode
  std::uint64_t seed = 1;         // --seed: scene generator seed (scene i uses seed + log2 N)
  double radius_low = 0.5, radius_high = 1.0;  // --radius-low / --radius-high
  double contacts_per_body = 0.4;              // --contacts-per-body
  std::string csv = "bench.csv";               // --csv
  bool plot = true;                            // --no-plot turns it off
  std::string plot_prefix;                     // --plot-prefix: PNG/SVG names; default: csv without ".csv"
  std::string plot_script;                     // --plot-script; default: see bench_plot_script()
};

struct BenchRow {
  std::uint64_t n = 0;
  std::int64_t contacts = -1;         // engine (first backend run); -1: not run
  std::int64_t bullet_contacts = -1;  // -1: Bullet not run
  double bullet_scratch_s = -1, bullet_warm_s = -1;
  std::map<Backend, double> engine_s;  // median seconds per backend run
  std::map<Backend, std::int64_t> engine_contacts;
  bool compared = false, agree = false;  // compared: at least two counts were measured
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
