#pragma once
// Internal to kernels/ (dem.cpp, dem_setup.cpp): the contact law of a material at a damping, and the
// bodies' mass properties at a density. Host code, g++-safe.
#include <vector>

#include "core/dem_step.hpp"
#include "dem.hpp"

namespace cg {

// Hertz–Mindlin's effective moduli of one material (equal bodies), the damping α, the friction and
// rolling friction.
dem::ContactLaw law_of(const dem::Material& m, double alpha);

// Each body's mass, inertia and fixed flag (spheres and ellipsoids of `density`).
std::vector<dem::BodyProps> props_of(const DemBodies& b, double density);

}  // namespace cg
