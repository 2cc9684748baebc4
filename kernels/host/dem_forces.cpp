// The contact stage of the granular dynamics on the CPU: contact_terms of every contact row
// (core/dem_step.hpp), OpenMP over the rows; then this step's springs become the last step's.
#include <omp.h>

#include "host/dem_stages.hpp"
#include "host/stages.hpp"

namespace cg::detail::host {

template <class Real>
void dem_contact_forces(HostDem& s, const dem::ContactRows<Real>& rows, const dem::StepConstants& c,
                        int threads, dem::Pass pass, const std::uint8_t* edge) {
  const std::size_t k = rows.count;
  if (pass != dem::Pass::interior) {
    for (auto* v :
         {&s.contact_force, &s.torque_a, &s.torque_b, &s.xi[1 - s.current], &s.normal[1 - s.current]})
      v->resize(k);
    s.contact_energy.resize(k);
  }
  const dem::BodyArrays b = s.arrays();
  const dem::ContactTerms t = s.terms();
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(k);
#pragma omp parallel for num_threads(threads) schedule(static) if (k > k_parallel_min / 8)
  for (std::ptrdiff_t i = 0; i < n; ++i)
    if (dem::contact_in_pass(std::size_t(i), rows, edge, pass))
      dem::contact_terms(std::size_t(i), rows, b, c, t);
  if (pass != dem::Pass::edge) s.current = 1 - s.current;
}

template void dem_contact_forces(HostDem&, const dem::ContactRows<float>&, const dem::StepConstants&, int,
                                 dem::Pass, const std::uint8_t*);
template void dem_contact_forces(HostDem&, const dem::ContactRows<double>&, const dem::StepConstants&, int,
                                 dem::Pass, const std::uint8_t*);

}  // namespace cg::detail::host
