#pragma once
// The scene families of `contactgrid study` (issue #13): each a seeded builder of the engine's input
// rows, sized by a scale factor (1: the default study, ~1–2 min on a 2-core machine for all modes).
//
//   uniform               radii uniform in [0.5, 1], 0.4 contacts per body (generate --kind uniform)
//   polydisperse-1:1000   log-uniform radii in [1e-3, 1] (generate --kind polydisperse --ratio 1000)
//   far-1e6, far-1e8      uniform, translated by (x, −x, x) with x = 1e6, 1e8
//   tangent-ulp-double    exactly tangent pairs (integer Pythagorean offsets scaled by 1/8, so d = ra + rb
//                         in binary), the second centre then moved by −1, 0 or +1 ulp of double per axis
//   tangent-ulp-float     the same with coordinates that are floats, moved by ±1 ulp of float
//   near-coincident       pairs whose centres are 0, 1e-3, 1e-6, 1e-9, 1e-12 apart, centres in [0, 100)³;
//                         a quarter as many pairs with an ellipsoid, 1e-3 … 1e-12 apart
//   dense-32-per-cell     radii uniform in [0.5, 1], 32 centres per cell of edge 2 (the largest diameter)
//   ellipsoids-tangent    pairs of ellipsoids of aspect 1, 2, 5, 10 (random orientations), made to touch
//                         at one point (support points of the exact reference), then moved apart along
//                         the normal by gaps of ±1e-2 … ±1e-8 and 0 (× the bounding radius)
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "io/scene_file.hpp"

namespace cg {

struct StudyFamily {
  std::string name;
  bool ellipsoids;  // the solver tolerance is one more axis of the study for these
  std::function<BodyRows(double scale, std::uint64_t seed)> make;
};

// Every family, in the study's order.
const std::vector<StudyFamily>& study_families();

// The engine's input view of rows built by a family (ids 0 … n−1, every pair reported).
BodiesView bodies_view(const BodyRows& rows);

}  // namespace cg
