// Host broad phase brute: every pair (a < b) whose boxes overlap, tested (see stages.hpp). The
// reference of the other broad phases, and the cheapest for a few dozen bodies.
#include "host/stages.hpp"

namespace cg::detail::host {

template <class Real>
std::uint64_t brute_candidates(const PackedBodies<Real>& p, std::span<const std::uint8_t> report,
                               CandidateFilter filter, const NarrowBodies<double>* fp64, int threads,
                               CandidatePairs& out) {
  const std::size_t n = p.spheres.size();
  const std::uint8_t* r = report.empty() ? nullptr : report.data();
  std::vector<Sphere<Real>> sphere(n);  // inflated by a skin
  for (std::size_t i = 0; i < n; ++i)
    sphere[i] = {p.spheres[i].x, p.spheres[i].y, p.spheres[i].z, p.spheres[i].r + p.inflation};
  return with_pair_test(filter, p, fp64, [&](const auto& test) {
    // rows of a: row a costs n − a, so the chunks (dynamic) are many
    return collect_pairs(n, 64, threads, out, [&](std::size_t i, auto&& emit) {
      const auto a = static_cast<std::uint32_t>(i);
      const Sphere<Real> sa = sphere[a];
      std::uint64_t tests = 0;
      for (std::uint32_t b = a + 1; b < n; ++b) {
        if (!boxes_overlap(sa, sphere[b]) || !pair_reported(r, a, b)) continue;
        ++tests;
        if (test(sa, sphere[b], a, b)) emit(a, b);
      }
      return tests;
    });
  });
}

template std::uint64_t brute_candidates(const PackedBodies<float>&, std::span<const std::uint8_t>,
                                        CandidateFilter, const NarrowBodies<double>*, int, CandidatePairs&);
template std::uint64_t brute_candidates(const PackedBodies<double>&, std::span<const std::uint8_t>,
                                        CandidateFilter, const NarrowBodies<double>*, int, CandidatePairs&);

}  // namespace cg::detail::host
