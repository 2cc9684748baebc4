#pragma once
// The exact reference (cg_reference): what "exact" means here, and the long-double vectors its
// solvers use. The library shares NO code with the engine's narrow phase (kernels/core): it has its
// own vectors, rotations and algorithms, so an error in one is not repeated in the other. The engine's
// headers are used only for the input types (Vec3<double>, BodiesView).
//
// "Exact" means:
//   - Arithmetic in long double, which on x86-64 is the 80-bit extended format: a 64-bit mantissa,
//     ε = 2^-63 ≈ 1.1e-19 (2048 times finer than double). Inputs are doubles (or floats), so each
//     input converts without rounding.
//   - Spheres: the closed form of docs/FORMAT.md §3 on the world doubles. A centre difference a − b of two
//     doubles is exact in long double when their exponents differ by at most 10 (and in double
//     already when they are within a factor 2, Sterbenz); otherwise it is rounded once, 2^-64 relative
//     to the larger. So the decision d² ≤ (ra + rb)² and the normal (a − b)/d carry ~1e-19 relative
//     error: exact for every input that double precision can tell apart (no frame shift, unlike the
//     engine, which subtracts a local origin first).
//   - Ellipsoids (ellipsoid_reference.hpp): the global minimum of the support-function
//     f(n) = h_A(−n) + h_B(n) − n·(a − b) by brute force over a Fibonacci sphere of directions plus
//     the principal axes, refined by Newton in long double; cross-checked in tests by the
//     Perram–Wertheim function. Converged to ~1e-17 of the bodies' size, not to the last bit.
//   - The rounding band: a pair whose exact |distance| is within the band of a precision mode may be
//     decided either way by that mode (docs/FORMAT.md §3: 16·ε_mode·(largest local coordinate + 2·r_max)).
//     Outside the band, every decision must equal the reference's. The reference's own error is
//     orders of magnitude below every mode's band.
#include <cmath>

namespace cg::exact {

using LD = long double;

// Digits of the reference arithmetic: 64 on x86-64 (80-bit long double), 53 where long double is
// double (the reference is then only as exact as fp64; the tests say so when it happens).
inline constexpr int kMantissaBits = __LDBL_MANT_DIG__;

struct V {
  LD x, y, z;
};
inline V add(V a, V b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline V sub(V a, V b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline V scale(LD s, V a) { return {s * a.x, s * a.y, s * a.z}; }
inline LD dotp(V a, V b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline LD norm(V a) { return std::sqrt(dotp(a, a)); }
inline V unit(V a) { return scale(1 / norm(a), a); }
inline V crossp(V a, V b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }

}  // namespace cg::exact
