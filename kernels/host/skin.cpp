// Host stage skin: the check of candidates kept across calls (EngineOptions::skin; see
// core/skin.hpp), and the keeping of a freshly built list with the state it was built from.
#include <algorithm>
#include <cmath>
#include <utility>

#include "host/stages.hpp"

namespace cg::detail::host {

Motion measure_motion(const BodiesView& bodies, const KeptCandidates& kept, int threads) {
  const std::size_t n = bodies.size();
  double moved_sq = 0, growth = 0;
  // max is exact, so the result does not depend on the thread count
  // clang-format off
#pragma omp parallel for num_threads(threads) schedule(static) reduction(max : moved_sq, growth) \
    if (n > k_parallel_min)
  // clang-format on
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3<double> d = bodies.position[i] - kept.position[i];
    moved_sq = std::max(moved_sq, d.x * d.x + d.y * d.y + d.z * d.z);
    growth = std::max(growth, bodies.radius[i] - kept.radius[i]);
  }
  Motion m;
  m.displacement = std::sqrt(moved_sq);
  m.growth = growth;
  m.report_changed =
      !std::equal(bodies.report.begin(), bodies.report.end(), kept.report.begin(), kept.report.end());
  return m;
}

void keep_candidates(const BodiesView& bodies, CandidatePairs&& c, KeptCandidates& kept) {
  kept.pairs = std::move(c);
  kept.position.assign(bodies.position.begin(), bodies.position.end());
  kept.radius.assign(bodies.radius.begin(), bodies.radius.end());
  kept.report.assign(bodies.report.begin(), bodies.report.end());
}

}  // namespace cg::detail::host
