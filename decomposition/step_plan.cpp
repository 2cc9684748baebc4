// The plan of the resident steps (see step_plan.hpp): roles and halo from the run's routing rules.
#include "step_plan.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

namespace cg {

const char* to_string(RowRole role) {
  switch (role) {
    case RowRole::interior:
      return "interior";
    case RowRole::boundary:
      return "boundary";
    case RowRole::ghost:
      return "ghost";
  }
  return "?";
}

std::size_t StepPlan::count(RowRole r) const {
  return static_cast<std::size_t>(std::count(role.begin(), role.end(), r));
}

StepPlan make_step_plan(const SlabDecomposition& slabs, int self, std::span<const double> coordinate,
                        double width, int threads) {
  if (self < 0 || self >= slabs.ranks())
    throw UsageError("step plan: rank " + std::to_string(self) + " is not in [0, " +
                     std::to_string(slabs.ranks()) + ")");
  if (!(width >= 0) || !std::isfinite(width))
    throw InputError("step plan: ghost width is not a finite value >= 0");
  const std::size_t n = coordinate.size();
  const std::size_t bad = first_bad(n, threads, [&](std::size_t i) { return !std::isfinite(coordinate[i]); });
  if (bad < n) throw InputError("step plan: row " + std::to_string(bad) + "'s coordinate is not finite");
  auto x = [coordinate](std::size_t i) { return coordinate[i]; };
  const auto owner = to_owner(slabs, x);
  const auto ghost_ranks = to_ghost_ranks(slabs, x, width);
  auto owned = [&](std::size_t i) {
    bool mine = false;
    owner(i, [&](int r) { mine = r == self; });
    return mine;
  };
  StepPlan plan;
  plan.role.resize(n);
  std::size_t owned_rows = 0;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(+ : owned_rows) \
    if (n > (std::size_t(1) << 14))
  for (std::size_t i = 0; i < n; ++i) {
    const bool mine = owned(i);
    bool sent = false;
    if (mine) ghost_ranks(i, [&](int) { sent = true; });
    plan.role[i] = !mine ? RowRole::ghost : sent ? RowRole::boundary : RowRole::interior;
    owned_rows += mine ? 1 : 0;
  }
  plan.owned = owned_rows;
  const ExportPlan boundary = route<std::size_t, std::allocator<std::size_t>>(
      n, 1, threads,
      [&](std::size_t i, auto&& emit) {
        if (plan.role[i] == RowRole::boundary) emit(0);
      },
      [](std::size_t i) { return i; });
  plan.boundary.assign(boundary.rows.begin(), boundary.rows.end());
  // The halo: the owned rows by to_ghost_ranks (a ghost row goes nowhere).
  plan.halo = route<std::size_t, std::allocator<std::size_t>>(
      n, slabs.ranks(), threads,
      [&](std::size_t i, auto&& emit) {
        if (plan.role[i] == RowRole::boundary) ghost_ranks(i, emit);
      },
      [](std::size_t i) { return i; });
  return plan;
}

BoundaryRows merge_boundary_rows(std::span<const std::int64_t> boundary_ids,
                                 std::span<const std::int64_t> ghost_ids) {
  for (std::size_t k = 1; k < boundary_ids.size(); ++k)
    if (!(boundary_ids[k - 1] < boundary_ids[k]))
      throw Error("engine B's rows: boundary ids not ascending at " + std::to_string(k) + ": internal error");
  // The ghosts in id order (the groups of the sources interleave in id).
  std::vector<std::size_t> by_id(ghost_ids.size());
  std::iota(by_id.begin(), by_id.end(), std::size_t(0));
  std::sort(by_id.begin(), by_id.end(),
            [&](std::size_t a, std::size_t b) { return ghost_ids[a] < ghost_ids[b]; });
  BoundaryRows rows;
  rows.of_boundary.resize(boundary_ids.size());
  rows.of_ghost.resize(ghost_ids.size());
  std::size_t k = 0, g = 0, row = 0;
  std::int64_t last = 0;
  while (k < boundary_ids.size() || g < by_id.size()) {
    const bool boundary =
        g == by_id.size() || (k < boundary_ids.size() && boundary_ids[k] < ghost_ids[by_id[g]]);
    const std::int64_t id = boundary ? boundary_ids[k] : ghost_ids[by_id[g]];
    if (row > 0 && id == last)
      throw Error("engine B's rows: body " + std::to_string(id) + " is held twice: internal error");
    last = id;
    if (boundary)
      rows.of_boundary[k++] = row++;
    else
      rows.of_ghost[by_id[g++]] = row++;
  }
  return rows;
}

}  // namespace cg
