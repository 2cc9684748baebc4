#pragma once
// The broad phases (EngineOptions::broad_phase), their plans and the rule of `auto` (g++-safe).
//
//   grid    Le Grand's uniform grid (core/grid.hpp): cells at least as wide as the largest body; a few
//           large bodies among small ones fill each cell with many small ones (cost quadratic in them)
//   levels  a hierarchy of grids (core/broad.hpp): one level per size class, each body in the level of
//           its size, pairs across levels found from the smaller body's side; near-linear whatever the
//           sizes
//   sweep   Baraff's sort and sweep: the boxes sorted by their lower face along the axis of largest
//           extent, each swept against the boxes that start before it ends
//   brute   every pair (tiled on the GPU): the reference, and the cheapest for a few dozen bodies
// All feed the same candidate list (sorted (a, b)) to the same narrow stage: the contacts are the same
// bits whichever runs (core/broad.hpp says why).
#include <cstdint>

#include "core/broad.hpp"
#include "grid_plan.hpp"

namespace cg {

enum class BroadPhase { automatic, grid, levels, sweep, brute };
const char* to_string(BroadPhase b);

// The levels of one call: level l holds the bodies of broad-phase radius in (top[l − 1], top[l]]
// (top of the last: +inf), its grid's cell edge the one the grid's cost model picks for the level's
// radii (tuned_cell_size, from the smallest valid edge for top[l] to 3 times it, at most the next
// level's smallest valid edge; the last level: the frame's edge). Consecutive tops differ by kLevelRatio
// (more where the radii span more than kLevelRatio^(kMaxLevels − 1)). Every level's grid covers the bounds
// and shares half_bits; keys are level << (half_bits + 3) | cell key, key_bits in all.
struct LevelsPlan {
  int count = 1;
  double top[kMaxLevels] = {};
  GridPlan grid[kMaxLevels];
  int half_bits = 0;
  int key_bits = 3;
  bool key64 = false;
};
inline constexpr double kLevelRatio = 2;

// The levels for bodies of these bounds in `frame` (its cell edge valid for the largest body);
// `radius_offset`: what the pair stage adds to each world radius (mixed's broad_margin, a skin's
// inflation). Levels whose grid could not be keyed (too many cells for the precision, more than 63
// key bits) are merged into the next one up.
LevelsPlan plan_levels(const Bounds& b, const Frame& frame, Precision p, double radius_offset);

// LevelParams of the broad phase's real type (core/broad.hpp) from the plan.
template <class Real>
LevelParams<Real> level_params(const LevelsPlan& plan, double radius_margin);

// The sweep's axis: the largest extent of the bounds (x, y, z = 0, 1, 2; the first of equal ones).
int sweep_axis(const Bounds& b);

// The bodies a cell of edge 2·r_max would hold on average: count · (2·r_max)³ over the volume of the
// bounds (each extent at least 2·r_max). The grid's pair tests grow with it.
double grid_occupancy(const Bounds& b);

// The contacts a body would have if the centres were spread uniformly over the bounds' box (each
// extent at least 2·r_max): ρ·(2π/3)·E[(r_a + r_b)³], ρ = count / volume, from the radius moments
// (r_sum; every radius r_max where they are absent). generate's density model, edges aside.
double expected_contacts_per_body(const Bounds& b);

// `auto`: the broad phase for bodies of these bounds (measured: BENCHMARKS.md §18, §20): brute for at
// most kBruteBodies bodies; levels where the largest radius exceeds kLevelsSpread times the mean one
// and the grid's cells, sized for the largest, would hold more than kOccupancyPerLevel bodies per
// level of the hierarchy (log2(2·r_max / r_min) levels: each costs every smaller body a lookup); else
// the grid (a wide radius law in a sparse scene, log-uniform 1:1000 among them, is the grid's).
// `device`: for the CUDA backend, whose grid pays more for crowded cells (its pair walk stages 32
// entries of a cell in shared memory and walks the rest of a longer cell from memory, one thread per
// entry), so levels take over from kOccupancyPerLevelDevice bodies per level (bimodal 1:10 among them),
// and a sparse scene of one size class of at least 2^21 bodies (fewer than kOneLevelContactsPerBody
// expected contacts a body) takes the levels' one-level walk in input order unless the call keeps its
// candidates (`skin`), which keeps the grid (broad_phase.cpp).
BroadPhase choose_broad_phase(const Bounds& b, Precision p, bool device = false, bool skin = false);
inline constexpr std::uint64_t kBruteBodies = 32;
inline constexpr double kLevelsSpread = 4;
inline constexpr double kOccupancyPerLevel = 64;
inline constexpr double kOccupancyPerLevelDevice = 4;
inline constexpr double kOneLevelContactsPerBody = 1.75;

}  // namespace cg
