// The integration stages of the granular dynamics on the CPU: kick_drift and kick of every body
// (core/dem_body.hpp), OpenMP over the bodies.
#include <omp.h>

#include "host/dem_stages.hpp"
#include "host/stages.hpp"

namespace cg::detail::host {

dem::BodyArrays HostDem::arrays() {
  return {position.data(),  velocity.data(),    omega.data(),
          momentum.data(),  orientation.data(), force.data(),
          torque.data(),    props.data(),       shape.empty() ? nullptr : shape.data(),
          semi_axes.data(), radius.data(),      position.size()};
}

dem::ContactTerms HostDem::terms() {
  const int next = 1 - current;
  return {contact_force.data(), torque_a.data(),     torque_b.data(),    contact_energy.data(),
          xi[next].data(),      normal[next].data(), xi[current].data(), normal[current].data()};
}

namespace {
template <class F>
void for_bodies(HostDem& s, int threads, F&& f) {
  const dem::BodyArrays b = s.arrays();
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(b.count);
#pragma omp parallel for num_threads(threads) schedule(static) if (b.count > k_parallel_min / 8)
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    dem::BodyState st = b.state(std::size_t(i));
    f(st, b.props[i], b.ellipsoid(std::size_t(i)));
    b.store(std::size_t(i), st);
  }
}
}  // namespace

void dem_kick_drift(HostDem& s, double dt, int threads) {
  for_bodies(s, threads,
             [dt](dem::BodyState& st, const dem::BodyProps& p, bool e) { dem::kick_drift(st, p, e, dt); });
}

void dem_kick(HostDem& s, double dt, int threads) {
  for_bodies(s, threads,
             [dt](dem::BodyState& st, const dem::BodyProps& p, bool e) { dem::kick(st, p, e, dt); });
}

}  // namespace cg::detail::host
