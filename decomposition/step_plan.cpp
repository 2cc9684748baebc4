// The plan of the resident steps (see step_plan.hpp): roles and halo from the run's routing rules.
#include "step_plan.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

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

namespace {

void check_plan_input(const SlabDecomposition& slabs, int self, std::span<const double> coordinate,
                      int threads) {
  if (self < 0 || self >= slabs.ranks())
    throw UsageError("step plan: rank " + std::to_string(self) + " is not in [0, " +
                     std::to_string(slabs.ranks()) + ")");
  const std::size_t n = coordinate.size();
  const std::size_t bad = first_bad(n, threads, [&](std::size_t i) { return !std::isfinite(coordinate[i]); });
  if (bad < n) throw InputError("step plan: row " + std::to_string(bad) + "'s coordinate is not finite");
}

// The rows listed by role (ascending), as route() lists them.
std::vector<std::size_t> rows_of(const std::vector<RowRole>& role, RowRole r, int threads) {
  const ExportPlan rows = route<std::size_t, std::allocator<std::size_t>>(
      role.size(), 1, threads,
      [&](std::size_t i, auto&& emit) {
        if (role[i] == r) emit(0);
      },
      [](std::size_t i) { return i; });
  return std::vector<std::size_t>(rows.rows.begin(), rows.rows.end());
}

// The plan by a halo rule `ghost_ranks(i, emit)` (routing.hpp's to_ghost_ranks or to_ghost_ranks_by).
template <class GhostRanks>
StepPlan plan_by(const SlabDecomposition& slabs, int self, std::span<const double> coordinate,
                 const GhostRanks& ghost_ranks, int threads) {
  const std::size_t n = coordinate.size();
  auto x = [coordinate](std::size_t i) { return coordinate[i]; };
  const auto owner = to_owner(slabs, x);
  auto owned = [&](std::size_t i) {
    bool mine = false;
    owner(i, [&](int r) { mine = r == self; });
    return mine;
  };
  StepPlan plan;
  plan.role.resize(n);
  // one pass: the roles, each chunk's boundary rows listed (ascending; the chunks in order)
  const Chunks c(n, threads);
  std::vector<std::vector<std::size_t>> found(static_cast<std::size_t>(c.parts));
  std::size_t owned_rows = 0;
#pragma omp parallel for num_threads(threads) schedule(static, 1) reduction(+ : owned_rows) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    std::vector<std::size_t>& mine_rows = found[static_cast<std::size_t>(t)];
    for (std::size_t i = c.begin(t), e = c.end(t); i < e; ++i) {
      const bool mine = owned(i);
      bool sent = false;
      if (mine) ghost_ranks(i, [&](int) { sent = true; });
      plan.role[i] = !mine ? RowRole::ghost : sent ? RowRole::boundary : RowRole::interior;
      owned_rows += mine ? 1 : 0;
      if (sent) mine_rows.push_back(i);
    }
  }
  plan.owned = owned_rows;
  for (const std::vector<std::size_t>& f : found)
    plan.boundary.insert(plan.boundary.end(), f.begin(), f.end());
  // The halo: the boundary rows by the rule (the few, not every row again).
  const std::vector<std::size_t>& boundary = plan.boundary;
  plan.halo = route<std::size_t, std::allocator<std::size_t>>(
      boundary.size(), slabs.ranks(), threads,
      [&](std::size_t k, auto&& emit) { ghost_ranks(boundary[k], emit); },
      [&](std::size_t k) { return boundary[k]; });
  return plan;
}

}  // namespace

StepPlan make_step_plan(const SlabDecomposition& slabs, int self, std::span<const double> coordinate,
                        double width, int threads) {
  if (!(width >= 0) || !std::isfinite(width))
    throw InputError("step plan: ghost width is not a finite value >= 0");
  check_plan_input(slabs, self, coordinate, threads);
  auto x = [coordinate](std::size_t i) { return coordinate[i]; };
  return plan_by(slabs, self, coordinate, to_ghost_ranks(slabs, x, width), threads);
}

StepPlan make_step_plan(const SlabDecomposition& slabs, int self, std::span<const double> coordinate,
                        std::span<const double> radius, const GhostRule& rule, int threads) {
  if (radius.size() != coordinate.size()) throw UsageError("step plan: one radius per coordinate");
  for (const double reach : {rule.narrow_reach, rule.wide_reach, rule.margin})
    if (!(reach >= 0) || !std::isfinite(reach))
      throw InputError("step plan: ghost width is not a finite value >= 0");
  check_plan_input(slabs, self, coordinate, threads);
  auto x = [coordinate](std::size_t i) { return coordinate[i]; };
  return plan_by(
      slabs, self, coordinate,
      to_ghost_ranks_by(slabs, x, [&rule, radius](std::size_t i) { return rule.width(radius[i]); }), threads);
}

StepPlan make_step_plan_of(const SlabDecomposition& slabs, int self, std::size_t n,
                           std::span<const std::size_t> candidates, std::span<const double> coordinate,
                           std::span<const double> radius, const GhostRule& rule, int threads,
                           StepPlan previous) {
  const std::size_t m = candidates.size();
  if (coordinate.size() != m || radius.size() != m)
    throw UsageError("step plan: one coordinate and one radius per candidate");
  if (first_bad(m, threads, [&](std::size_t k) {
        return candidates[k] >= n || (k > 0 && !(candidates[k - 1] < candidates[k]));
      }) < m)
    throw UsageError("step plan: candidates not ascending rows below " + std::to_string(n));
  for (const double reach : {rule.narrow_reach, rule.wide_reach, rule.margin})
    if (!(reach >= 0) || !std::isfinite(reach))
      throw InputError("step plan: ghost width is not a finite value >= 0");
  check_plan_input(slabs, self, coordinate, threads);
  // the candidates' plan (rows k of the candidates), then its rows named as the held rows
  auto x = [coordinate](std::size_t k) { return coordinate[k]; };
  StepPlan of = plan_by(
      slabs, self, coordinate,
      to_ghost_ranks_by(slabs, x, [&rule, radius](std::size_t k) { return rule.width(radius[k]); }), threads);
  // the previous plan's role storage (a layout's n rows: no fresh pages to fault in)
  StepPlan plan;
  plan.role = std::move(previous.role);
  const bool parallel = n > (std::size_t(1) << 16);
  if (n > plan.role.capacity()) {  // grown with room (a migration moves a few rows): no copy, no refault
    plan.role.clear();
    plan.role.reserve(n + n / 16);
  }
  plan.role.resize(n);
  RowRole* role = plan.role.data();
#pragma omp parallel num_threads(threads) if (parallel)
  {
#pragma omp for schedule(static)
    for (std::size_t i = 0; i < n; ++i) role[i] = RowRole::interior;
#pragma omp for schedule(static)
    for (std::size_t k = 0; k < m; ++k) role[candidates[k]] = of.role[k];
  }
  plan.owned = n - (m - of.owned);
  plan.boundary.resize(of.boundary.size());
  plan.halo = std::move(of.halo);
  std::size_t* halo = plan.halo.rows.data();
  const std::size_t nb = of.boundary.size(), nh = plan.halo.rows.size();
#pragma omp parallel num_threads(threads) if (nb + nh > (std::size_t(1) << 14))
  {
#pragma omp for schedule(static) nowait
    for (std::size_t j = 0; j < nb; ++j) plan.boundary[j] = candidates[of.boundary[j]];
#pragma omp for schedule(static)
    for (std::size_t j = 0; j < nh; ++j) halo[j] = candidates[halo[j]];
  }
  return plan;
}

Band interior_band(const SlabDecomposition& slabs, int self, double max_width) {
  const double lo = slabs.lower(self), hi = slabs.upper(self);
  double scale = max_width;
  for (const double b : {lo, hi})
    if (std::isfinite(b)) scale = std::max(scale, std::abs(b));
  const double w = max_width + 1e-9 * scale;  // the rounding of x ± w is ~1e-16 of the scale
  return {lo + w, hi - w};
}

std::size_t add_wide_partners(StepPlan& plan, std::span<const double> coordinate,
                              std::span<const double> radius, std::span<const double> wide_coordinate,
                              std::span<const double> wide_radius, const GhostRule& rule, int threads) {
  if (radius.size() != coordinate.size() || coordinate.size() != plan.role.size() ||
      wide_radius.size() != wide_coordinate.size())
    throw UsageError("step plan: one radius per coordinate and one role per row");
  if (wide_coordinate.empty()) return 0;
  // the slab-axis intervals the wide ghosts reach (beyond the margin), merged: sorted, disjoint
  std::vector<std::pair<double, double>> reach(wide_coordinate.size());
  for (std::size_t g = 0; g < reach.size(); ++g) {
    const double w = wide_radius[g] + rule.margin;
    reach[g] = {wide_coordinate[g] - w, wide_coordinate[g] + w};
  }
  std::sort(reach.begin(), reach.end());
  std::vector<double> lo, hi;
  for (const auto& [a, b] : reach) {
    if (!hi.empty() && a <= hi.back()) {
      hi.back() = std::max(hi.back(), b);
    } else {
      lo.push_back(a);
      hi.push_back(b);
    }
  }
  const std::size_t n = coordinate.size();
  std::size_t added = 0;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(+ : added) if (n > (std::size_t(1) << 14))
  for (std::size_t i = 0; i < n; ++i) {
    if (plan.role[i] != RowRole::interior) continue;
    // the last interval starting at or below the row's top: the row meets the union iff it meets it
    const double top = coordinate[i] + radius[i], bottom = coordinate[i] - radius[i];
    const std::size_t k = static_cast<std::size_t>(std::upper_bound(lo.begin(), lo.end(), top) - lo.begin());
    if (k > 0 && hi[k - 1] >= bottom) {
      plan.role[i] = RowRole::boundary;
      ++added;
    }
  }
  if (added > 0) plan.boundary = rows_of(plan.role, RowRole::boundary, threads);
  return added;
}

BoundaryRows merge_boundary_rows(std::span<const std::int64_t> boundary_ids,
                                 std::span<const std::int64_t> ghost_ids, int threads) {
  const std::size_t nb = boundary_ids.size(), ng = ghost_ids.size(), total = nb + ng;
  const std::size_t unordered = first_bad(
      nb, threads, [&](std::size_t k) { return k > 0 && !(boundary_ids[k - 1] < boundary_ids[k]); });
  if (unordered < nb)
    throw Error("engine B's rows: boundary ids not ascending at " + std::to_string(unordered) +
                ": internal error");
  // The ghosts in id order: each source's run is ascending, so the runs are merged (few: one a
  // neighbouring rank), or sorted when there are many.
  std::vector<std::size_t> by_id(ng);
  std::iota(by_id.begin(), by_id.end(), std::size_t(0));
  const auto by_ghost_id = [&](std::size_t a, std::size_t b) { return ghost_ids[a] < ghost_ids[b]; };
  std::vector<std::size_t> run_end;
  for (std::size_t g = 1; g <= ng; ++g)
    if (g == ng || ghost_ids[g] < ghost_ids[g - 1]) run_end.push_back(g);
  if (run_end.size() > 8) {
    std::sort(by_id.begin(), by_id.end(), by_ghost_id);
  } else {
    for (std::size_t r = 1; r < run_end.size(); ++r)
      std::inplace_merge(by_id.begin(), by_id.begin() + static_cast<std::ptrdiff_t>(run_end[r - 1]),
                         by_id.begin() + static_cast<std::ptrdiff_t>(run_end[r]), by_ghost_id);
  }
  auto ghost = [&](std::size_t g) { return ghost_ids[by_id[g]]; };
  BoundaryRows rows;
  rows.of_boundary.resize(nb);
  rows.of_ghost.resize(ng);
  // The merge in parts of the output (a boundary row goes first when its id is smaller): part t's
  // rows [total·t/T, total·(t+1)/T) start at the boundary row where the merge path crosses that
  // diagonal; each part checks its own rows for an id held twice, then the parts' seams.
  const int parts = total > (std::size_t(1) << 16) ? std::max(1, threads) : 1;
  std::vector<std::int64_t> first(static_cast<std::size_t>(parts)), last(static_cast<std::size_t>(parts));
  std::vector<std::uint8_t> twice(static_cast<std::size_t>(parts), 0);
  std::vector<std::int64_t> twice_id(static_cast<std::size_t>(parts), 0);
#pragma omp parallel for num_threads(parts) schedule(static, 1) if (parts > 1)
  for (int t = 0; t < parts; ++t) {
    const std::size_t d = total * std::size_t(t) / std::size_t(parts),
                      e = total * std::size_t(t + 1) / std::size_t(parts);
    std::size_t lo = d > ng ? d - ng : 0, hi = std::min(d, nb);
    while (lo < hi) {
      const std::size_t mid = lo + (hi - lo) / 2;
      if (boundary_ids[mid] < ghost(d - mid - 1))
        lo = mid + 1;
      else
        hi = mid;
    }
    std::size_t k = lo, g = d - lo;
    const auto ut = static_cast<std::size_t>(t);
    for (std::size_t row = d; row < e; ++row) {
      const bool boundary = g == ng || (k < nb && boundary_ids[k] < ghost(g));
      const std::int64_t id = boundary ? boundary_ids[k] : ghost(g);
      if (row == d) first[ut] = id;
      if (row > d && id == last[ut] && !twice[ut]) {
        twice[ut] = 1;
        twice_id[ut] = id;
      }
      last[ut] = id;
      if (boundary)
        rows.of_boundary[k++] = row;
      else
        rows.of_ghost[by_id[g++]] = row;
    }
  }
  for (std::size_t t = 0; t < static_cast<std::size_t>(parts); ++t) {
    const std::size_t begin = total * t / std::size_t(parts);
    const bool seam = t > 0 && begin > total * (t - 1) / std::size_t(parts) &&
                      total * (t + 1) / std::size_t(parts) > begin && first[t] == last[t - 1];
    if (twice[t] || seam)
      throw Error("engine B's rows: body " + std::to_string(twice[t] ? twice_id[t] : first[t]) +
                  " is held twice: internal error");
  }
  return rows;
}

}  // namespace cg
