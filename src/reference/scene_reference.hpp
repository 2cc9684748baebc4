#pragma once
// The exact reference of a whole scene of spheres and ellipsoids (the engine's input rows,
// BodiesView): every pair whose exact distance is <= slack, sorted by (a, b). Sphere pairs by the
// closed form (sphere_reference.hpp); pairs with an ellipsoid by the global minimisation of
// ellipsoid_reference.hpp over the pairs whose bounding spheres come within slack.
#include <vector>

#include "bodies.hpp"
#include "reference/sphere_reference.hpp"

namespace cg::exact {

struct SceneReferenceOptions {
  LD slack = 0;                  // keep pairs with exact distance <= slack (a rounding band)
  int ellipsoid_samples = 4000;  // Fibonacci directions per ellipsoid pair (exact_contact)
};

// Ids are row indices (bodies.id is ignored). Precondition: valid rows (the engine's checks).
std::vector<RefContact> reference_contacts(const BodiesView& bodies, const SceneReferenceOptions& options);

}  // namespace cg::exact
