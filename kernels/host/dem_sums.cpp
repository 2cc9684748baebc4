// The body stage of the granular dynamics on the CPU: where each body's contact rows lie (rows sorted
// by A: their begins; a stable counting sort of the rows by B), then body_terms of every body
// (core/dem_step.hpp: the sums in a fixed order, walls, gravity), OpenMP over the bodies.
#include <omp.h>

#include "host/dem_stages.hpp"
#include "host/stages.hpp"

namespace cg::detail::host {

template <class Real>
void dem_body_index(HostDem& s, const dem::ContactRows<Real>& rows) {
  const std::size_t n = s.size(), k = rows.count;
  // counts of each body as A and as B, their exclusive scans: the begins
  s.a_begin.assign(n + 1, 0);
  s.b_begin.assign(n + 1, 0);
  for (std::size_t r = 0; r < k; ++r) {
    ++s.a_begin[static_cast<std::size_t>(rows.id_a[r]) + 1];
    ++s.b_begin[static_cast<std::size_t>(rows.id_b[r]) + 1];
  }
  for (std::size_t i = 0; i < n; ++i) {
    s.a_begin[i + 1] += s.a_begin[i];
    s.b_begin[i + 1] += s.b_begin[i];
  }
  // the rows by B, in row order within a body (stable)
  s.by_b.resize(k);
  std::vector<std::uint32_t> at(s.b_begin.begin(), s.b_begin.end() - 1);
  for (std::size_t r = 0; r < k; ++r) s.by_b[at[static_cast<std::size_t>(rows.id_b[r])]++] = std::uint32_t(r);
}

void dem_body_terms(HostDem& s, const dem::StepConstants& c, int threads, dem::Pass pass,
                    const std::uint8_t* edge, bool kick_and_drift) {
  const std::size_t n = s.size();
  s.wall_xi.resize(n * std::size_t(c.wall_count));
  s.wall_energy.resize(n);
  const dem::BodyArrays b = s.arrays();
  const dem::ContactTerms t{s.contact_force.data(),
                            s.torque_a.data(),
                            s.torque_b.data(),
                            s.contact_energy.data(),
                            nullptr,
                            nullptr,
                            nullptr,
                            nullptr};
  const dem::BodyRowIndex index{s.a_begin.data(), s.b_begin.data(), s.by_b.data()};
  const dem::WallTerms w{s.wall_xi.data(), s.wall_energy.data()};
  const std::ptrdiff_t nn = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min / 8)
  for (std::ptrdiff_t i = 0; i < nn; ++i) {
    const std::size_t j = std::size_t(i);
    if (!dem::body_in_pass(j, edge, pass)) continue;
    dem::body_terms(j, b, c, t, index, w);
    if (!kick_and_drift) continue;
    dem::BodyState st = b.state(j);
    const bool ell = b.ellipsoid(j);
    dem::kick(st, b.props[j], ell, c.dt);
    dem::kick_drift(st, b.props[j], ell, c.dt);
    b.store(j, st);
  }
}

template <class Real>
void dem_body_forces(HostDem& s, const dem::ContactRows<Real>& rows, const dem::StepConstants& c,
                     int threads) {
  dem_body_index(s, rows);
  dem_body_terms(s, c, threads, dem::Pass::all, nullptr, false);
}

template void dem_body_index(HostDem&, const dem::ContactRows<float>&);
template void dem_body_index(HostDem&, const dem::ContactRows<double>&);
template void dem_body_forces(HostDem&, const dem::ContactRows<float>&, const dem::StepConstants&, int);
template void dem_body_forces(HostDem&, const dem::ContactRows<double>&, const dem::StepConstants&, int);

}  // namespace cg::detail::host
