// Slab geometry (see slab_decomposition.hpp): axis choice, cuts by quantiles or widths, owner.
// Pure: no MPI, no CUDA.
#include "slab_decomposition.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace cg {

int choose_axis(const Bounds& global, int forced) {
  if (forced >= 0) {
    if (forced > 2) throw UsageError("slab axis " + std::to_string(forced) + " is not 0, 1 or 2");
    return forced;
  }
  int best = 0;
  double best_extent = component(global.hi, 0) - component(global.lo, 0);
  for (int k = 1; k < 3; ++k) {
    double e = component(global.hi, k) - component(global.lo, k);
    if (e > best_extent) {
      best = k;
      best_extent = e;
    }
  }
  return best;
}

double ghost_width(double r_max, double extent, double epsilon) {
  // A pair reported by the engine satisfies |d|^2 <= (ra + rb)^2 in Real on local coordinates that
  // each carry an absolute error <= epsilon·extent; the squares and sums add a few relative epsilon.
  // 16 epsilon (relative and absolute) is a comfortable bound of both.
  return 2.0 * r_max * (1.0 + 16.0 * epsilon) + 16.0 * epsilon * std::abs(extent);
}

double frame_extent(const Bounds& global, const Vec3<double>& origin) {
  double extent = 0;
  for (int k = 0; k < 3; ++k) {
    const double o = component(origin, k);
    extent = std::max({extent, std::abs(component(global.hi, k) - o), std::abs(component(global.lo, k) - o)});
  }
  return extent;
}

double frame_ghost_width(const Bounds& global, const Vec3<double>& origin, double epsilon, double reach) {
  return ghost_width(global.r_max, frame_extent(global, origin) + reach, epsilon);
}

GhostRule GhostRule::uniform(double w) {
  GhostRule g;
  g.narrow = std::numeric_limits<double>::infinity();
  g.narrow_reach = w;
  g.wide_reach = w;
  g.per_radius = false;
  return g;
}

GhostRule ghost_rule(const Bounds& global, double extent, double epsilon, double reach) {
  const double r_max = global.r_max;
  const double mean = global.count > 0 ? global.r_sum[0] / double(global.count) : r_max;
  GhostRule g;
  g.margin = ghost_width(r_max, extent + reach, epsilon) - 2 * r_max + reach;
  g.narrow = mean > 0 ? std::min(r_max, kLevelsSpread * mean) : r_max;
  g.narrow_reach = g.narrow + g.margin;
  g.wide_reach = r_max + g.margin;
  return g;
}

SlabDecomposition::SlabDecomposition(int axis, std::vector<double> cuts)
    : m_axis(axis), m_cuts(std::move(cuts)) {
  if (axis < 0 || axis > 2) throw UsageError("slab axis " + std::to_string(axis) + " is not 0, 1 or 2");
  for (std::size_t i = 0; i < m_cuts.size(); ++i) {
    if (!std::isfinite(m_cuts[i])) throw InputError("slab cut " + std::to_string(i + 1) + " is not finite");
    if (i > 0 && m_cuts[i] < m_cuts[i - 1]) {
      throw InputError("slab cuts are not sorted at cut " + std::to_string(i + 1));
    }
  }
}

SlabDecomposition SlabDecomposition::from_sorted_sample(int axis, std::span<const double> sorted_sample,
                                                        int ranks) {
  if (ranks < 1) throw UsageError("slab decomposition needs at least one rank");
  std::vector<double> cuts(static_cast<std::size_t>(ranks - 1), 0.0);
  const std::size_t s = sorted_sample.size();
  if (s > 0) {
    for (int r = 1; r < ranks; ++r) {
      // floor(r·S/P): r < 2^31 and S < 2^33 (the sample is held in memory), so r·S < 2^64.
      std::size_t i = static_cast<std::size_t>(std::uint64_t(r) * std::uint64_t(s) / std::uint64_t(ranks));
      cuts[static_cast<std::size_t>(r - 1)] = sorted_sample[std::min(i, s - 1)];
    }
  }
  return SlabDecomposition(axis, std::move(cuts));
}

SlabDecomposition SlabDecomposition::from_sample(int axis, std::vector<double> sample, int ranks) {
  // from_sorted_sample reads only the P-1 quantile positions floor(r·S/P): put the right order
  // statistic at each (successive selections on the remaining upper part) instead of sorting.
  const std::size_t n_s = sample.size();
  if (ranks > 64) {
    std::sort(sample.begin(), sample.end());
  } else {
    std::size_t from = 0;
    for (int r = 1; r < ranks && n_s > 0; ++r) {
      const std::size_t q = std::min<std::size_t>(
          n_s - 1, static_cast<std::size_t>(std::uint64_t(r) * std::uint64_t(n_s) / std::uint64_t(ranks)));
      if (q < from) continue;  // already in place (equal quantile positions)
      std::nth_element(sample.begin() + static_cast<std::ptrdiff_t>(from),
                       sample.begin() + static_cast<std::ptrdiff_t>(q), sample.end());
      from = q + 1;
    }
  }
  return from_sorted_sample(axis, sample, ranks);
}

SlabDecomposition SlabDecomposition::equal_width(int axis, double lo, double hi, int ranks) {
  if (ranks < 1) throw UsageError("slab decomposition needs at least one rank");
  if (!(std::isfinite(lo) && std::isfinite(hi) && lo <= hi)) {
    throw InputError("equal-width slabs need finite bounds lo <= hi");
  }
  std::vector<double> cuts(static_cast<std::size_t>(ranks - 1));
  for (int r = 1; r < ranks; ++r) {
    double t = static_cast<double>(r) / ranks;
    cuts[static_cast<std::size_t>(r - 1)] = std::min(hi, std::max(lo, lo + t * (hi - lo)));
  }
  return SlabDecomposition(axis, std::move(cuts));
}

double SlabDecomposition::lower(int rank) const {
  return rank == 0 ? -std::numeric_limits<double>::infinity() : m_cuts[static_cast<std::size_t>(rank - 1)];
}

double SlabDecomposition::upper(int rank) const {
  return rank == ranks() - 1 ? std::numeric_limits<double>::infinity()
                             : m_cuts[static_cast<std::size_t>(rank)];
}

int SlabDecomposition::owner(double x) const {
  return static_cast<int>(std::upper_bound(m_cuts.begin(), m_cuts.end(), x) - m_cuts.begin());
}

}  // namespace cg
