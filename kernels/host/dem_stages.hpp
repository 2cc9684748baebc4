#pragma once
// The CPU backend of the granular dynamics (kernels/dem.hpp): its state in HOST memory and its
// stages, one file each (dem_integrate.cpp, dem_forces.cpp, dem_sums.cpp, dem_energy.cpp), loops of
// OpenMP threads over the per-item functions of core/dem_step.hpp — the oracle of the CUDA backend.
#include <cstdint>
#include <vector>

#include "core/dem_step.hpp"
#include "dem.hpp"

namespace cg::detail::host {

struct HostDem {
  // bodies
  std::vector<Vec3<double>> position, velocity, omega, momentum, force, torque;
  std::vector<Quat<double>> orientation;
  std::vector<dem::BodyProps> props;
  std::vector<Shape> shape;  // empty: all spheres
  std::vector<Vec3<double>> semi_axes;
  std::vector<double> radius;
  // the contacts' terms (row order) and the springs carried between steps (this step's and the last)
  std::vector<Vec3<double>> contact_force, torque_a, torque_b;
  std::vector<double> contact_energy;
  std::vector<Vec3<double>> xi[2], normal[2];
  int current = 0;  // xi[current], normal[current]: the last step's
  // walls: springs (body-major) and energies; the rows' order by B
  std::vector<Vec3<double>> wall_xi;
  std::vector<double> wall_energy;
  std::vector<std::uint32_t> a_begin, b_begin, by_b;

  std::size_t size() const { return position.size(); }
  dem::BodyArrays arrays();
  dem::ContactTerms terms();  // this step's (writes the other xi/normal buffer)
};

// kick_drift / kick of every body (core/dem_body.hpp).
void dem_kick_drift(HostDem& s, double dt, int threads);
void dem_kick(HostDem& s, double dt, int threads);

// contact_terms of every row of `pass` (dem::Pass; edge: the rows' edge flags); then, after the
// last pass (all or interior), the rows' springs are the last step's (current flips).
template <class Real>
void dem_contact_forces(HostDem& s, const dem::ContactRows<Real>& rows, const dem::StepConstants& c,
                        int threads, dem::Pass pass = dem::Pass::all, const std::uint8_t* edge = nullptr);

// The rows' order by B (a stable counting sort) and where each body's rows begin (dem_body_index),
// then body_terms of every body of `pass` (its force and torque of the step; kick_and_drift: then its
// kick and the next step's kick_drift, the same operations as the separate stages); dem_body_forces:
// both, every body.
template <class Real>
void dem_body_index(HostDem& s, const dem::ContactRows<Real>& rows);
void dem_body_terms(HostDem& s, const dem::StepConstants& c, int threads, dem::Pass pass,
                    const std::uint8_t* edge, bool kick_and_drift);
template <class Real>
void dem_body_forces(HostDem& s, const dem::ContactRows<Real>& rows, const dem::StepConstants& c,
                     int threads);

// The energies, summed in the tree of chunks of core/dem_sum.hpp (as the device).
DemEnergies dem_energies(HostDem& s, std::size_t contacts, Vec3<double> gravity, int threads);

}  // namespace cg::detail::host
