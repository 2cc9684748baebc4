// Host broad phase levels: a hierarchy of grids (core/broad.hpp). Per body its level and its cells in
// that level's grid, the (key, body) entries of all levels in one array (keys carry the level above
// the cell key), and the pairs of two levels from the smaller body's side (see stages.hpp).
#include <algorithm>

#include "host/stages.hpp"

namespace cg::detail::host {

template <class Real>
void level_cells(const LevelParams<Real>& lp, int threads, PackedBodies<Real>& p) {
  const std::size_t n = p.spheres.size();
  p.level.resize(n);
  p.cells.resize(n);
  p.ctrl.resize(n);
  p.count.resize(n);
  const bool cut = p.box_cells();
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    const Sphere<Real> s0 = p.spheres[i];
    const Sphere<Real> s{s0.x, s0.y, s0.z, s0.r + p.inflation};
    const int l = level_of(s.r, lp);
    p.level[i] = static_cast<std::uint8_t>(l);
    p.cells[i] = cut ? cut_cells(s, p.cut[i], lp.grid[l]) : body_cells(s, lp.grid[l]);
    p.ctrl[i] = control_bits(p.cells[i]);
    p.count[i] = entry_count(p.cells[i]);
  }
}

template <class Real, class Key>
std::uint64_t level_entries(PackedBodies<Real>& p, const LevelParams<Real>& lp, int threads,
                            Entries<Key>& out) {
  const std::size_t n = p.cells.size();
  std::vector<std::uint64_t> offset;
  const std::uint64_t n_entries = exclusive_scan_into(p.count, offset);
  out.keys.resize(n_entries);
  out.body.resize(n_entries);
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    const int l = p.level[i];
    const Key level = Key(l) << lp.key_shift;
    for (std::uint32_t m = 0; m < p.count[i]; ++m) {
      out.keys[offset[i] + m] = level | body_cell_key<Key>(p.cells[i], m, lp.grid[l]);
      out.body[offset[i] + m] = static_cast<std::uint32_t>(i);
    }
  }
  p.cells = {};
  p.count = {};
  return n_entries;
}

namespace {

// Where each level's run of the sorted keys starts; begin[lp.count] = the entry count (empty levels
// are skipped by every query).
template <class Real, class Key>
void level_runs(const Entries<Key>& e, const LevelParams<Real>& lp, std::size_t* begin) {
  for (int l = 0; l < lp.count; ++l)
    begin[l] = lower_bound_key(e.keys.data(), std::size_t(0), e.size(), Key(Key(l) << lp.key_shift));
  begin[lp.count] = e.size();  // (count << key_shift may not fit the key)
}

}  // namespace

template <class Real, class Key>
std::uint64_t cross_level_estimate(const Entries<Key>& e, const PackedBodies<Real>& p,
                                   const LevelParams<Real>& lp, int threads) {
  if (lp.count < 2) return 0;
  std::size_t begin[kMaxLevels + 1];
  level_runs(e, lp, begin);
  const bool cut = p.box_cells();
  const std::size_t n = p.spheres.size();
  std::uint64_t tests = 0;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(+ : tests) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    if (p.level[i] + 1 >= lp.count) continue;
    const Sphere<Real> s0 = p.spheres[i];
    const Sphere<Real> s{s0.x, s0.y, s0.z, s0.r + p.inflation};
    tests += cross_level_bound(p.level[i], lp, e.keys.data(), begin, [&](const GridParams<Real>& g) {
      return cut ? cut_cells(s, p.cut[i], g) : body_cells(s, g);
    });
  }
  return tests;
}

template <class Real, class Key>
std::uint64_t cross_level_candidates(const Entries<Key>& e, const PackedBodies<Real>& p,
                                     const LevelParams<Real>& lp, std::span<const std::uint8_t> report,
                                     CandidateFilter filter, const NarrowBodies<double>* fp64, int threads,
                                     CandidatePairs& out) {
  if (lp.count < 2) return 0;
  const std::uint8_t* r = report.empty() ? nullptr : report.data();
  std::size_t begin[kMaxLevels + 1];
  level_runs(e, lp, begin);
  const bool cut = p.box_cells();
  return with_pair_test(filter, p, fp64, [&](const auto& test) {
    return collect_pairs(p.spheres.size(), 1024, threads, out, [&](std::size_t i, auto&& emit) {
      const auto a = static_cast<std::uint32_t>(i);
      const Sphere<Real> s0 = p.spheres[a];
      const Sphere<Real> sa{s0.x, s0.y, s0.z, s0.r + p.inflation};
      const auto cells_in = [&](const GridParams<Real>& g) {
        return cut ? cut_cells(sa, p.cut[a], g) : body_cells(sa, g);
      };
      return cross_level_pairs(a, p.level[a], lp, e.keys.data(), e.body.data(), begin, p.ctrl.data(), r,
                               cells_in, [&](std::uint32_t b) {
                                 const Sphere<Real> t0 = p.spheres[b];
                                 const Sphere<Real> sb{t0.x, t0.y, t0.z, t0.r + p.inflation};
                                 if (test(sa, sb, a, b)) emit(std::min(a, b), std::max(a, b));
                               });
    });
  });
}

template void level_cells(const LevelParams<float>&, int, PackedBodies<float>&);
template void level_cells(const LevelParams<double>&, int, PackedBodies<double>&);
#define CG_LEVELS(R, K)                                                                                \
  template std::uint64_t level_entries(PackedBodies<R>&, const LevelParams<R>&, int, Entries<K>&);     \
  template std::uint64_t cross_level_estimate(const Entries<K>&, const PackedBodies<R>&,               \
                                              const LevelParams<R>&, int);                             \
  template std::uint64_t cross_level_candidates(                                                       \
      const Entries<K>&, const PackedBodies<R>&, const LevelParams<R>&, std::span<const std::uint8_t>, \
      CandidateFilter, const NarrowBodies<double>*, int, CandidatePairs&);
CG_LEVELS(float, std::uint32_t)
CG_LEVELS(float, std::uint64_t)
CG_LEVELS(double, std::uint32_t)
CG_LEVELS(double, std::uint64_t)
#undef CG_LEVELS

}  // namespace cg::detail::host
