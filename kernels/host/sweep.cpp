// Host broad phase sweep: Baraff's sort and sweep along one axis (see stages.hpp).
#include <algorithm>

#include "host/radix_sort.hpp"
#include "host/stages.hpp"

namespace cg::detail::host {
namespace {
// The body's box along `axis`: its lower and upper faces, rounded as boxes_overlap rounds them.
template <class Real>
Real lower_face(const Sphere<Real>& s, Real inflation, int axis) {
  return axis_of(s, axis) - box_radius(s.r + inflation);
}
template <class Real>
Real upper_face(const Sphere<Real>& s, Real inflation, int axis) {
  return axis_of(s, axis) + box_radius(s.r + inflation);
}
}  // namespace

template <class Real>
void sweep_sort(const PackedBodies<Real>& p, int axis, int threads, SweepOrder& out) {
  using Bits = decltype(orderable_bits(Real(0)));
  const std::size_t n = p.spheres.size();
  std::vector<Bits> keys(n);
  out.body.resize(n);
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    keys[i] = orderable_bits(lower_face(p.spheres[i], p.inflation, axis));
    out.body[i] = static_cast<std::uint32_t>(i);
  }
  radix_sort(keys, out.body, int(8 * sizeof(Bits)), threads);
}

template <class Real>
std::uint64_t sweep_candidates(const SweepOrder& order, const PackedBodies<Real>& p, int axis,
                               std::span<const std::uint8_t> report, CandidateFilter filter,
                               const NarrowBodies<double>* fp64, int threads, CandidatePairs& out) {
  const std::size_t n = order.body.size();
  const std::uint8_t* r = report.empty() ? nullptr : report.data();
  // the inflated spheres and the lower faces in sorted order, read in sequence by the sweep
  std::vector<Sphere<Real>> sphere(n);
  std::vector<Real> lower(n);
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t k = 0; k < n; ++k) {
    const Sphere<Real> s = p.spheres[order.body[k]];
    sphere[k] = {s.x, s.y, s.z, s.r + p.inflation};
    lower[k] = lower_face(s, p.inflation, axis);
  }
  return with_pair_test(filter, p, fp64, [&](const auto& test) {
    return collect_pairs(n, 1024, threads, out, [&](std::size_t k, auto&& emit) {
      const Sphere<Real> sa = sphere[k];
      const Real end = upper_face(p.spheres[order.body[k]], p.inflation, axis);
      const std::uint32_t a = order.body[k];
      std::uint64_t tests = 0;
      for (std::size_t l = k + 1; l < n && lower[l] <= end; ++l) {
        const std::uint32_t b = order.body[l];
        if (!boxes_overlap(sa, sphere[l]) || !pair_reported(r, a, b)) continue;
        ++tests;
        if (test(sa, sphere[l], a, b)) emit(std::min(a, b), std::max(a, b));
      }
      return tests;
    });
  });
}

template <class Real>
PairEstimate sweep_estimate(const SweepOrder& order, const PackedBodies<Real>& p, int axis, int threads) {
  const std::size_t n = order.body.size();
  std::vector<Real> lower(n);
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t k = 0; k < n; ++k) lower[k] = lower_face(p.spheres[order.body[k]], p.inflation, axis);
  std::uint64_t tests = 0, largest = 0;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(+ : tests) reduction(max : largest) \
    if (n > k_parallel_min)
  for (std::size_t k = 0; k < n; ++k) {
    // the later places the sweep of k passes: those whose lower face is at most its upper face
    const Real end = upper_face(p.spheres[order.body[k]], p.inflation, axis);
    const std::uint64_t m = static_cast<std::uint64_t>(
        std::upper_bound(lower.begin() + static_cast<std::ptrdiff_t>(k) + 1, lower.end(), end) -
        lower.begin() - static_cast<std::ptrdiff_t>(k) - 1);
    tests += m;
    largest = std::max(largest, m);
  }
  return {tests, n, n, largest};
}

template void sweep_sort(const PackedBodies<float>&, int, int, SweepOrder&);
template void sweep_sort(const PackedBodies<double>&, int, int, SweepOrder&);
template PairEstimate sweep_estimate(const SweepOrder&, const PackedBodies<float>&, int, int);
template PairEstimate sweep_estimate(const SweepOrder&, const PackedBodies<double>&, int, int);
template std::uint64_t sweep_candidates(const SweepOrder&, const PackedBodies<float>&, int,
                                        std::span<const std::uint8_t>, CandidateFilter,
                                        const NarrowBodies<double>*, int, CandidatePairs&);
template std::uint64_t sweep_candidates(const SweepOrder&, const PackedBodies<double>&, int,
                                        std::span<const std::uint8_t>, CandidateFilter,
                                        const NarrowBodies<double>*, int, CandidatePairs&);

}  // namespace cg::detail::host
