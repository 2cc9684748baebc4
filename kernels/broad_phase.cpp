// The broad phases' plans (levels, the sweep's axis) and the rule of `auto`.
#include "broad_phase.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <string_view>

#include "backend.hpp"  // bits_for
#include "errors.hpp"

namespace cg {

const char* to_string(BroadPhase b) {
  switch (b) {
    case BroadPhase::automatic:
      return "auto";
    case BroadPhase::grid:
      return "grid";
    case BroadPhase::levels:
      return "levels";
    case BroadPhase::sweep:
      return "sweep";
    case BroadPhase::brute:
      return "brute";
  }
  return "?";
}

namespace {
// How a level below the top one sizes its cells (CONTACTGRID_LEVELS_CELLS=smallest: the smallest valid
// edge for the level's largest radius, the plan's former rule, for before/after measurements).
bool tuned_level_cells() {
  static const bool tuned = [] {
    const char* v = std::getenv("CONTACTGRID_LEVELS_CELLS");
    return v == nullptr || std::string_view(v) != "smallest";
  }();
  return tuned;
}

// The cell edge of a level below the top one (radii in (bottom, top], the next level's top `next`, +inf
// for the top level): the grid's cost model (tuned_cell_size: entries against pair-walk steps) for the
// level, at most the next level's smallest valid edge (the frame's for the top level), so edges never
// shrink up the levels. The model takes every body of the scene into the level, each of the level's
// smallest radius: the finest level of a mixed scene holds most bodies (a bimodal mix's grains, all of
// one radius), whose boxes then span fewer cells of a wider edge, as the one-level grid's tuned cells
// do for a scene of one size.
double level_cell_size(const Bounds& b, const Frame& frame, Precision p, double bottom, double top,
                       double next) {
  Bounds level = b;
  level.r_max = top;
  const double smallest = std::min(frame.cell_size, min_cell_size(level, p));
  if (!tuned_level_cells() || !(bottom > 0)) return smallest;
  Bounds above = b;
  above.r_max = next;
  const double cap = std::isinf(next) ? frame.cell_size : std::min(frame.cell_size, min_cell_size(above, p));
  const double n = double(b.count);
  level.r_sum[0] = n * bottom;
  level.r_sum[1] = n * bottom * bottom;
  level.r_sum[2] = n * bottom * bottom * bottom;
  return std::max(smallest, std::min(cap, tuned_cell_size(level, p)));
}

// The plan of levels with these tops (the last +inf), or false when a level's grid cannot be keyed;
// `bottom`: the smallest radius of the first level.
bool try_levels(const Bounds& b, const Frame& frame, Precision p, const double* tops, int count,
                double bottom, LevelsPlan& out) {
  out = LevelsPlan{};
  out.count = count;
  int half_bits = 0;
  for (int l = 0; l < count; ++l) {
    out.top[l] = tops[l];
    Frame f = frame;
    if (l + 1 < count)
      f.cell_size = level_cell_size(b, frame, p, l == 0 ? bottom : tops[l - 1], tops[l], tops[l + 1]);
    try {
      out.grid[l] = plan_grid(b, f, p);
    } catch (const InputError&) {
      return false;  // too many cells for the precision's coordinates or for a 64-bit key
    }
    half_bits = std::max(half_bits, out.grid[l].half_bits);
  }
  out.half_bits = half_bits;
  out.key_bits = half_bits + 3 + detail::bits_for(std::uint64_t(count));
  out.key64 = out.key_bits > 32;
  if (out.key_bits > 63) return false;
  for (int l = 0; l < count; ++l) {
    out.grid[l].half_bits = half_bits;
    out.grid[l].key_bits = half_bits + 3;
    out.grid[l].key64 = out.key64;
  }
  return true;
}
}  // namespace

LevelsPlan plan_levels(const Bounds& b, const Frame& frame, Precision p, double radius_offset) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  const double lo = b.r_min + radius_offset, hi = b.r_max + radius_offset;
  double tops[kMaxLevels];
  int count = 1;
  if (b.count > 0 && lo > 0 && hi > lo) {
    const double ratio = std::max(kLevelRatio, std::pow(hi / lo, 1.0 / (kMaxLevels - 1)) * (1 + 1e-12));
    for (double t = lo * ratio; t < hi && count < kMaxLevels; t *= ratio) tops[count++ - 1] = t;
  }
  tops[count - 1] = inf;
  Bounds boxes = b;  // the boxes the pair stage sees, the radii grown by the offset
  boxes.lo = {b.lo.x - radius_offset, b.lo.y - radius_offset, b.lo.z - radius_offset};
  boxes.hi = {b.hi.x + radius_offset, b.hi.y + radius_offset, b.hi.z + radius_offset};
  // A level whose cell edge is not below 3/4 of the next one's (the rounding margin of far-off
  // coordinates dominates the smallest edges) joins it: it would only add a lookup.
  double kept[kMaxLevels];
  int n_kept = 0;
  double above = frame.cell_size;
  kept[kMaxLevels - 1] = inf;
  for (int l = count - 2; l >= 0; --l) {
    Bounds level = boxes;
    level.r_max = tops[l];
    const double cell = std::min(frame.cell_size, min_cell_size(level, p));
    if (cell > 0.75 * above) continue;
    kept[kMaxLevels - 2 - n_kept++] = tops[l];
    above = cell;
  }
  const double* first_top = kept + (kMaxLevels - 1 - n_kept);
  count = n_kept + 1;
  LevelsPlan plan;
  // The finest levels go first when their grids cannot be keyed: their bodies join the next level.
  for (int first = 0; first < count; ++first)
    if (try_levels(boxes, frame, p, first_top + first, count - first, first == 0 ? lo : first_top[first - 1],
                   plan))
      return plan;
  return plan;  // (not reached: one level is the grid of the frame, which the caller planned)
}

template <class Real>
LevelParams<Real> level_params(const LevelsPlan& plan, double radius_margin) {
  LevelParams<Real> lp{};
  lp.count = plan.count;
  lp.key_shift = plan.half_bits + 3;
  for (int l = 0; l < plan.count; ++l) {
    // rounded to Real: a body at most half an ulp above the planned top still fits the level's cell,
    // whose 16·ε margin covers it (+inf stays +inf)
    lp.top[l] = static_cast<Real>(plan.top[l]);
    lp.grid[l] = detail::grid_params<Real>(plan.grid[l], radius_margin);
  }
  return lp;
}
template LevelParams<float> level_params<float>(const LevelsPlan&, double);
template LevelParams<double> level_params<double>(const LevelsPlan&, double);

int sweep_axis(const Bounds& b) {
  const double e[3] = {b.hi.x - b.lo.x, b.hi.y - b.lo.y, b.hi.z - b.lo.z};
  return e[0] >= e[1] && e[0] >= e[2] ? 0 : (e[1] >= e[2] ? 1 : 2);
}

namespace {
double bounds_volume(const Bounds& b) {
  const double d = 2 * b.r_max;
  return std::max(b.hi.x - b.lo.x, d) * std::max(b.hi.y - b.lo.y, d) * std::max(b.hi.z - b.lo.z, d);
}
}  // namespace

double grid_occupancy(const Bounds& b) {
  const double d = 2 * b.r_max, volume = bounds_volume(b);
  return volume > 0 ? double(b.count) * d * d * d / volume : double(b.count);
}

double expected_contacts_per_body(const Bounds& b) {
  const double n = double(b.count), volume = bounds_volume(b);
  if (!(n > 0) || !(volume > 0)) return 0;
  const bool moments = b.r_sum[0] > 0 && b.r_sum[1] > 0 && b.r_sum[2] > 0;
  const double m1 = moments ? b.r_sum[0] / n : b.r_max, m2 = moments ? b.r_sum[1] / n : b.r_max * b.r_max,
               m3 = moments ? b.r_sum[2] / n : b.r_max * b.r_max * b.r_max;
  const double sum_cubed = 2 * m3 + 6 * m2 * m1;  // E[(r_a + r_b)³] of two independent radii
  return n / volume * (2.0 * std::acos(-1.0) / 3.0) * sum_cubed;
}

// `auto` on the device for a sparse scene of one size class (r_max <= kLevelRatio · r_min: the levels
// plan one level, the grid of the frame) of at least this many bodies: the levels, the same grid walked
// with the bodies in input order, where the grid renumbers them by z layer once they outgrow the L2
// (one-level levels is the faster from 2^22 bodies on an H100, not below 2^21: BENCHMARKS.md §22, §24).
// Sparse: below kOneLevelContactsPerBody expected contacts a body; denser scenes walk more pairs a
// body, where the grid's renumbered order pays (2^24 on an H200: the levels 0.87x the grid's time at
// 0.4 contacts a body, 0.91x at 1, 0.95x at 1.5, 1.05x at 2, 1.05–1.07x at 3 to 6; BENCHMARKS.md §34). Calls
// that keep their candidates (a skin) keep the grid: the measurement was of fresh detections, and the steps'
// builds reuse the grid's candidate buffers.
constexpr std::uint64_t kOneLevelDeviceBodies = std::uint64_t(1) << 21;

BroadPhase choose_broad_phase(const Bounds& b, Precision, bool device, bool skin) {
  if (b.count <= kBruteBodies) return BroadPhase::brute;
  if (device && !skin && b.count >= kOneLevelDeviceBodies && b.r_max <= kLevelRatio * b.r_min &&
      expected_contacts_per_body(b) < kOneLevelContactsPerBody)
    return BroadPhase::levels;
  const double mean = b.count > 0 ? b.r_sum[0] / double(b.count) : b.r_max;
  if (!(mean > 0 && b.r_max > kLevelsSpread * mean)) return BroadPhase::grid;
  const double levels = std::log2(2 * b.r_max / std::max(b.r_min, b.r_max * 1e-300));
  const double per_level = device ? kOccupancyPerLevelDevice : kOccupancyPerLevel;
  return grid_occupancy(b) > per_level * levels ? BroadPhase::levels : BroadPhase::grid;
}

}  // namespace cg
