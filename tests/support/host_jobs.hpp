#pragma once
// The CPU stage tests' shared pieces: the CONTACTGRID_HOST_ENTRIES knob for a guard's life, and a
// detection job of spheres (the frame and grid a run from scratch would plan).
#include <cstdlib>

#include "host/stages.hpp"
#include "scenes.hpp"

namespace cg::test {

// CONTACTGRID_HOST_ENTRIES=<value> for the guard's life (`cells`, `body-order`, `grouped`).
class HostEntriesKnob {
 public:
  explicit HostEntriesKnob(const char* value) { ::setenv("CONTACTGRID_HOST_ENTRIES", value, 1); }
  ~HostEntriesKnob() { ::unsetenv("CONTACTGRID_HOST_ENTRIES"); }
  HostEntriesKnob(const HostEntriesKnob&) = delete;
  HostEntriesKnob& operator=(const HostEntriesKnob&) = delete;
};

// The detection job of spheres `s` in Real's precision, basic fields.
template <class Real>
detail::DetectJob<Real> make_job(const Spheres& s) {
  constexpr Precision prec = sizeof(Real) == 4 ? Precision::fp32 : Precision::fp64;
  const BodiesView v{s.p, s.r, {}, {}};
  const Bounds b = compute_bounds(v);
  const Frame f = make_frame(b, 0, prec, CellChoice::tuned);
  detail::DetectJob<Real> job{v, plan_grid(b, f, prec), {}, Fields::basic};
  job.grid = detail::grid_params<Real>(job.plan);
  return job;
}

}  // namespace cg::test
