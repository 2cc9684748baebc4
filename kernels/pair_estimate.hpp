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
  std::uint64_t tests = 0;    // pair tests the pair stage would make, at most
  std::uint64_t bodies = 0;   // bodies of the call (owned and ghosts)
  std::uint64_t entries = 0;  // cell entries (a grid: home and phantom cells), or the broad phase's items
  std::uint64_t largest = 0;  // the most entries in one cell (or bucket)
};

// What the engine does with an estimate (EngineOptions::max_pair_tests, on_pair_estimate).
struct PairLimits {
  std::uint64_t max_tests = 0;                                // 0: no limit
  const std::function<void(const PairEstimate&)>* on_estimate = nullptr;  // may be null
};

// Far above the usual: at least 1e9 tests (seconds of work) and 1000 per body.
bool pair_work_unusual(const PairEstimate& e);

// "about 5.0e+11 pair tests (5.0e+05 per body; the fullest cell holds 1000000 entries)"
std::string describe(const PairEstimate& e);

// Before a pair stage: hands the estimate to limits.on_estimate (when set), then throws LimitError
// ("... exceeds --max-pair-tests N ...") when it is above limits.max_tests (when set).
void check_pair_estimate(const PairEstimate& e, const PairLimits& limits);

}  // namespace cg
