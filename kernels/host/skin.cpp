// Host stage skin: the check of candidates kept across calls (EngineOptions::skin; see
// core/skin.hpp), and the keeping of a freshly built list with the state it was built from.
#include <algorithm>
#include <cmath>
#include <utility>

#include "host/stages.hpp"

namespace cg::detail::host {

namespace {
// A cut list (core/centre_cut.hpp): the largest move of a point of a body (its centre's, and an
// ellipsoid's turn: turned_motion, the device's arithmetic) and whether a body's kind or semi-axes
// changed since the build, and whether an ellipsoid turned.
void measure_turns(const BodiesView& bodies, const KeptCandidates& kept, int threads, Motion& m) {
  const std::size_t n = bodies.size();
  double moved = 0;
  int changed = 0, turned = 0;
  // clang-format off
#pragma omp parallel for num_threads(threads) schedule(static) reduction(max : moved, changed, turned) \
    if (n > k_parallel_min)
  // clang-format on
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3<double> d = bodies.position[i] - kept.position[i];
    const bool ellipsoid = bodies.shape[i] == Shape::ellipsoid;
    if (bodies.shape[i] != kept.shape[i] || (ellipsoid && !(bodies.semi_axes[i].x == kept.semi_axes[i].x &&
                                                            bodies.semi_axes[i].y == kept.semi_axes[i].y &&
                                                            bodies.semi_axes[i].z == kept.semi_axes[i].z)))
      changed = 1;
    const Quat<double> q = bodies.orientation[i], q0 = kept.orientation[i];
    if (ellipsoid && !(q.w == q0.w && q.x == q0.x && q.y == q0.y && q.z == q0.z)) turned = 1;
    const double qa[4] = {q.w, q.x, q.y, q.z}, q0a[4] = {q0.w, q0.x, q0.y, q0.z};
    const double mi = ellipsoid ? turned_motion(d.x, d.y, d.z, bodies.radius[i], qa, q0a)
                                : cg_sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    moved = std::max(moved, mi);
  }
  m.displacement = moved;
  m.shape_changed = changed != 0;
  m.turned = turned != 0;
}
}  // namespace

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
  if (kept.pairs.filter == CandidateFilter::centre_cut) {
    if (bodies.shape.size() != n || kept.shape.size() != n)
      m.shape_changed = true;
    else
      measure_turns(bodies, kept, threads, m);
  }
  return m;
}

void keep_candidates(const BodiesView& bodies, CandidatePairs&& c, KeptCandidates& kept) {
  kept.pairs = std::move(c);
  kept.position.assign(bodies.position.begin(), bodies.position.end());
  kept.radius.assign(bodies.radius.begin(), bodies.radius.end());
  kept.report.assign(bodies.report.begin(), bodies.report.end());
  const bool cut = kept.pairs.filter == CandidateFilter::centre_cut;
  kept.shape.assign(cut ? bodies.shape.begin() : bodies.shape.end(), bodies.shape.end());
  kept.semi_axes.assign(cut ? bodies.semi_axes.begin() : bodies.semi_axes.end(), bodies.semi_axes.end());
  kept.orientation.assign(cut ? bodies.orientation.begin() : bodies.orientation.end(),
                          bodies.orientation.end());
}

}  // namespace cg::detail::host
