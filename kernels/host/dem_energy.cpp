// The energies of the granular dynamics on the CPU, in the fixed order of core/dem_sum.hpp (a tree of
// chunk sums, each level's chunks over the threads), so they equal the device's.
#include <omp.h>

#include "core/dem_sum.hpp"
#include "host/dem_stages.hpp"

namespace cg::detail::host {

namespace {
template <class F>
double fixed_sum(std::size_t n, int threads, F&& value) {
  return dem::tree_sum(n, value, [threads](std::size_t chunks, auto&& f) {
    const std::ptrdiff_t nc = static_cast<std::ptrdiff_t>(chunks);
#pragma omp parallel for num_threads(threads) schedule(static) if (chunks > 64)
    for (std::ptrdiff_t c = 0; c < nc; ++c) f(std::size_t(c));
  });
}
}  // namespace

DemEnergies dem_energies(HostDem& s, std::size_t contacts, Vec3<double> gravity, int threads) {
  const dem::BodyArrays b = s.arrays();
  DemEnergies e;
  e.kinetic =
      fixed_sum(b.count, threads, [&](std::size_t i) { return dem::body_energy(i, b, gravity).kinetic; });
  e.gravity =
      fixed_sum(b.count, threads, [&](std::size_t i) { return dem::body_energy(i, b, gravity).gravity; });
  const double* ce = s.contact_energy.data();
  const double* we = s.wall_energy.data();
  e.elastic = fixed_sum(contacts, threads, [ce](std::size_t k) { return ce[k]; }) +
              fixed_sum(s.wall_energy.size(), threads, [we](std::size_t i) { return we[i]; });
  return e;
}

}  // namespace cg::detail::host
