#pragma once
// --precision auto (issue #13 item 2, docs/PRECISION.md): the cheapest precision mode
// whose documented bounds hold for this scene at the accuracy the user accepts (--accuracy). Pure host
// code on the run's agreed global bounds, so every rank of an MPI run picks the same mode.
#include <array>
#include <exception>
#include <optional>
#include <string>

#include "engine.hpp"

namespace cg {

// --accuracy POS[,ANGLE]: the error the user accepts on every contact.
//   position   |p − p_exact| <= position · r_min for every contact point, r_min the scene's smallest
//              bounding radius. The modes' position bounds are absolute lengths (the world coordinates'
//              spacing and the frame's rounding), so relative to the smallest body they are the worst
//              over all contacts: a bound relative to r_max would promise the small bodies of a 1:1000
//              scene 1000× less than it says.
//              Unset (no --accuracy): what fp64 gives for this scene, so a user who asks for nothing
//              never gets a less accurate answer than fp64's (mixed's answers are fp64's bit for bit).
//   angle_deg  the angle between normal_on_b and the exact normal; unset: no separate requirement.
struct Accuracy {
  std::optional<double> position;
  std::optional<double> angle_deg;
};

// What the choice reads of a scene: all from the global bounds every rank agreed on.
struct PrecisionScene {
  double extent = 0;     // L: the largest local coordinate (the frame's origin is the lower corner)
  double world_max = 0;  // X: the largest |world coordinate| of the bounds
  double r_min = 0, r_max = 0;
  // Scenes with ellipsoids never take fp32. Its pairs with nearly coincident centres are fp64's (issue
  // #13), but its ellipsoid normals are bounded by the fp32 solver tolerance: 5e-4·κ rad for axis
  // ratio κ (tests/unit/test_ellipsoid_contact.cpp; the study measured 0.053° at κ <= 10), above
  // fp32's √3·2^-12 rad (0.024°) and growing with κ, which the global bounds do not carry.
  bool ellipsoids = false;
  // Why a mode cannot run this scene at all (empty: it can), indexed by Precision: fp32's float32 world
  // positions spaced above r_max/4 (check_fp32_world), a float broad phase's grid beyond 2^22 cells
  // per axis, a --cell-size below the mode's smallest valid edge.
  std::array<std::string, 3> refusal;
  std::array<std::exception_ptr, 3> refusal_error;  // the error itself (UsageError, InputError)
};

// From the global bounds and the run's cell-size request: make_frame and plan_grid tried per mode.
PrecisionScene precision_scene(const Bounds& global, bool ellipsoids, double cell_size, CellChoice choice);

// A mode's documented bounds for a scene (docs/PRECISION.md, "a few" set to 4), for the
// point's Euclidean error (√3 × the per-coordinate bound) and the normal's angle:
//   fp64, mixed  position √3·(½ ulp64(X) + 4·ε64·r_max);                          normal 4·ε64 rad
//   fp32         position √3·(½ ulp32(X) + 4·ε32·(L + r_max)) + r_max·θ32;  normal θ32 = √3·2^−12 rad
// fp32's r_max·θ32: a normal off by θ32 moves the point centre ± r·n by r·θ32 (centres just above the
// separation below which the normal is recomputed in fp64). Centres within ε of the precision take
// the normal (1, 0, 0) (docs/FORMAT.md §3): those pairs are the contract's, not these bounds'.
struct ModeBounds {
  double position = 0;   // absolute length
  double angle_deg = 0;  // degrees
};
ModeBounds mode_bounds(Precision mode, const PrecisionScene& scene);

// The modes from the cheapest, per backend (measured: docs/PRECISION.md, BENCHMARKS §9).
const std::array<Precision, 3>& cost_order(Backend backend);

struct PrecisionChoice {
  Precision mode = Precision::fp64;
  std::string reason;  // one line: the pick, its bounds here, and why each cheaper mode was passed over
};

// The first mode of cost_order(backend) (backend: cpu or cuda) that can run the scene and whose
// bounds meet `accuracy`. When no mode can run the scene, rethrows fp64's refusal (what --precision
// fp64 says: a --cell-size too small is a UsageError); when none meets the accuracy, throws InputError
// (exit 3) saying what each mode gives here.
PrecisionChoice choose_precision(const PrecisionScene& scene, Backend backend, const Accuracy& accuracy);

}  // namespace cg
