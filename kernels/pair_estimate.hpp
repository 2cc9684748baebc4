#pragma once
// Runaway work: the pair tests a broad phase is about to make, estimated before its pair stage, and
// the one check every broad phase makes with its estimate (docs/ERRORS.md "Runaway scenes").
// g++-safe public header.
//
// A uniform grid tests each pair of entries that share a cell (less what the cell rule assigns to
// another cell), so Σ over cells of m·(m − 1)/2, m the cell's entries, bounds its tests from above; it
// comes from the sorted cell keys in one pass (host: kernels/host/pairs.cpp, CUDA:
// kernels/cuda/pair_estimate.cuh). Usual scenes test a few to a few hundred pairs per body; a scene
// whose bodies crowd into few cells (a cell sized for a radius far above the rest, bodies stacked on
// one point) tests a number that grows with the square of the bodies and can run for hours.
// A broad phase of another kind (a tree, sweep and prune) provides its own PairEstimate (its leaves'
// or overlaps' pair count) and calls check_pair_estimate before its pair stage in the same way.
#include <cstdint>
#include <functional>
#include <string>

namespace cg {

struct PairEstimate {
  std::uint64_t tests = 0;      // pair tests the pair stage would make, at most
  std::uint64_t bodies = 0;     // bodies of the call (owned and ghosts)
  std::uint64_t entries = 0;    // cell entries (a grid: home and phantom cells), or the broad phase's items
  std::uint64_t largest = 0;    // the most entries in one cell (or bucket)
  double tests_per_second = 0;  // the backend's rate for such tests (below); 0: no time estimate
};

// The rates behind the time estimate: pair tests a second of the engine's detection of a pile (bodies
// stacked in one cell, every test a candidate and a contact: pairs, order, narrow and, on the GPU, the
// download of the rows), the slowest case; the host's per thread. On the GPU the pile's contacts, not
// its tests, take the time (ordering and downloading them); tests that find no contact run thousands
// of times faster. Writing as many contacts to a file comes on top. BENCHMARKS.md "Runaway scenes"
// gives the measurements behind them.
constexpr double kHostPairTestsPerSecondPerThread = 4e6;
constexpr double kDevicePairTestsPerSecond = 1.5e7;

// What the engine does with an estimate (EngineOptions::max_pair_tests, on_pair_estimate).
struct PairLimits {
  std::uint64_t max_tests = 0;                                            // 0: no limit
  const std::function<void(const PairEstimate&)>* on_estimate = nullptr;  // may be null
  // The pair stage's progress: tests done so far, from one thread at a time, and once more with
  // finished = true at the stage's end (the host backend always; the CUDA backend when the estimate
  // is far above the usual: follows_progress). May be null.
  const std::function<void(std::uint64_t done, bool finished)>* on_progress = nullptr;
  // Whether anyone looks at the estimate — a limit, a caller that sees it, or one that follows the
  // progress, which a GPU grid pair stage reports only when its estimate is far above the usual: a broad
  // phase makes none otherwise (the library's default costs nothing; on the GPU the estimate is a
  // scan, a reduction and a wait).
  bool wanted() const {
    return max_tests > 0 || (on_estimate != nullptr && *on_estimate) ||
           (on_progress != nullptr && *on_progress);
  }
};

// Far above the usual: at least 1e9 tests (seconds of work) and 1000 per body.
bool pair_work_unusual(const PairEstimate& e);

// Whether a pair stage with this estimate reports its progress: far above the usual, and a caller
// follows it (PairLimits::on_progress). The host's pair stage reports whenever a caller follows it; a
// GPU pair stage is one kernel that the host would otherwise wait for without a word.
bool follows_progress(const PairEstimate& e, const PairLimits& limits);

// "about 5e+11 pair tests (5e+05 per body; the fullest cell holds 1000000 entries)", and with a rate
// "…; about 4.2 min at 2e+09 tests a second)"
std::string describe(const PairEstimate& e);

// "42 s", "12 min", "3.5 h", "2.1 days"
std::string describe_seconds(double seconds);

// Before a pair stage: hands the estimate to limits.on_estimate (when set), then throws LimitError
// ("... exceeds --max-pair-tests N ...") when it is above limits.max_tests (when set).
void check_pair_estimate(const PairEstimate& e, const PairLimits& limits);

}  // namespace cg
