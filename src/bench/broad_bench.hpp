#pragma once
// `contactgrid bench-broad`: the broad phases (grid, levels, sweep, brute, and the pick of auto) ×
// scene families × N on one backend: a table, and a CSV. No Bullet needed.
//
// Families (generate_scene, seeded; the generator's density, 0.4 contacts per body, or
// `contacts_per_body`):
//   uniform          radii U[0.5, 1]: the reference row of every N
//   bimodal10        bimodal 1:10, 10 % of the volume in the large bodies (r = 1 among r = 0.1)
//   bimodal100       bimodal 1:100, 10 % of the volume in the large bodies (r = 1 among r = 0.01)
//   loguniform1000   polydisperse, radii log-uniform over 1:1000 (0.001 … 1)
//   intruder1        one body of r = 1 among grains of r = 0.01 (issue #34's CPU case)
//   intruders64      64 bodies of r = 100 among grains of r = 1 (issue #34's GPU case)
// Timing: per (family, N) the bodies are made resident (Engine::set_resident), one untimed warm-up,
// then the median of `repetitions` detect_resident() calls (wall clock, or CPU time: cpu_time; CUDA:
// the contacts stay on the device). A broad phase whose run at some N took longer than `budget_s` is not run
// at larger N of that family ("-"); brute runs while N <= 2^brute_hi, sweep while N <= 2^sweep_hi; a broad
// phase whose warm-up and repetitions at this N are predicted to take longer than `limit_s` is skipped,
// its predicted seconds a call shown as ">t" (the prediction: its time at the family's previous N grown
// as N^e, e from its last two times at smaller N, clamped to [1, 2]; from one time: 1 for grid and
// levels, 2 for sweep and brute). `auto` is the broad phase the engine picks for the row (the same
// rule, on the same bounds), its time the picked phase's of that row where that was run (the same code
// is not timed twice). Every broad phase of a row must find the same number of contacts (else the
// command fails: they are the same bits). Columns: seconds per broad phase; auto with the letter of its
// pick; best = the fastest; auto/best; ns per contact of the best; the best against the uniform row's
// best at that N (/uniform: time; /unif/c: time per contact). A last line counts the rows where auto is
// within 10 % of the best.
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "engine.hpp"

namespace cg {

struct BroadBenchOptions {
  std::vector<std::string> families;  // default: all
  std::vector<BroadPhase> phases;     // the broad phases timed (default: all); with auto, its pick too
  int lo = 12, hi = 16;               // N = 2^lo … 2^hi, step `step`
  int step = 2;
  Backend backend = Backend::cpu;
  Precision precision = Precision::fp64;
  int repetitions = 3;
  int threads = 0;
  int brute_hi = 14, sweep_hi = 16;
  double budget_s = 30;
  double limit_s = 60;  // predicted seconds (warm-up and repetitions) above which a run is skipped; 0: none
  // Time the process's CPU time (all threads) instead of the wall clock: on a machine shared with
  // other work, with threads = 1, the work itself rather than the waits (CPU backend only).
  bool cpu_time = false;
  // Print, under each row, every timed broad phase's stage times of its last repetition (ms), its
  // levels, (cell, body) entries, pair tests and candidates: where a family's time goes.
  bool stage_times = false;
  // Make the pair estimate before each pair stage, as `detect` does (it follows the estimate for its
  // warning and --max-pair-tests); the library's calls make none unless asked.
  bool estimate = false;
  std::uint64_t seed = 1;
  // The families' density (generate's --contacts-per-body): the rule of `auto` weighs the grid's
  // crowding, so its crossovers are measured at the densities a scene may have.
  double contacts_per_body = 0.4;
  std::string csv;
};

const std::vector<std::string>& broad_bench_families();

// Runs the study, printing the table to `out`; throws on a contact-count disagreement.
void run_broad_bench(const BroadBenchOptions& options, std::ostream& out);

}  // namespace cg
