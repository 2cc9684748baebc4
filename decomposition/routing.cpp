// The owner and halo plans as row indices (see routing.hpp): the run's route() exporting indices.
#include "routing.hpp"

namespace cg {

ExportPlan make_owner_plan(const SlabDecomposition& slabs, std::span<const double> coordinate, int threads) {
  auto x = [coordinate](std::size_t i) { return coordinate[i]; };
  return route<std::size_t, std::allocator<std::size_t>>(coordinate.size(), slabs.ranks(), threads,
                                                         to_owner(slabs, x), [](std::size_t i) { return i; });
}

ExportPlan make_halo_plan(const SlabDecomposition& slabs, int self, std::span<const double> coordinate,
                          double ghost_width, int threads) {
  if (self < 0 || self >= slabs.ranks()) {
    throw UsageError("halo plan: rank " + std::to_string(self) + " is not in [0, " +
                     std::to_string(slabs.ranks()) + ")");
  }
  auto x = [coordinate](std::size_t i) { return coordinate[i]; };
  check_halo_rows(slabs, self, coordinate.size(), x, ghost_width, threads);
  return route<std::size_t, std::allocator<std::size_t>>(coordinate.size(), slabs.ranks(), threads,
                                                         to_ghost_ranks(slabs, x, ghost_width),
                                                         [](std::size_t i) { return i; });
}

ExportPlan make_halo_plan(const SlabDecomposition& slabs, int self, std::span<const double> coordinate,
                          std::span<const double> radius, const GhostRule& rule, int threads) {
  if (self < 0 || self >= slabs.ranks()) {
    throw UsageError("halo plan: rank " + std::to_string(self) + " is not in [0, " +
                     std::to_string(slabs.ranks()) + ")");
  }
  if (radius.size() != coordinate.size()) throw UsageError("halo plan: one radius per coordinate");
  auto x = [coordinate](std::size_t i) { return coordinate[i]; };
  const double r_max = radius.empty() ? 0.0 : *std::max_element(radius.begin(), radius.end());
  check_halo_rows(slabs, self, coordinate.size(), x, rule.max_width(r_max), threads);
  return route<std::size_t, std::allocator<std::size_t>>(
      coordinate.size(), slabs.ranks(), threads,
      to_ghost_ranks_by(slabs, x, [&rule, radius](std::size_t i) { return rule.width(radius[i]); }),
      [](std::size_t i) { return i; });
}

}  // namespace cg
