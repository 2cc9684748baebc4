// --precision auto: the documented bounds of each mode for one scene, and the cheapest mode that meets
// the user's accuracy (precision_choice.hpp).
#include "precision_choice.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

namespace cg {

namespace {

constexpr double kRadToDeg = 57.295779513082320876798;
constexpr double kEps32 = std::numeric_limits<float>::epsilon();
constexpr double kEps64 = std::numeric_limits<double>::epsilon();
constexpr double kFp32Normal = 1.7320508075688772 / 4096;  // √3·2^−12 rad (fp32's normal bound)

double ulp64(double x) { return std::nextafter(x, std::numeric_limits<double>::infinity()) - x; }
double ulp32(double x) {
  const float f = float(x);
  return double(std::nextafter(f, std::numeric_limits<float>::infinity())) - double(f);
}

std::size_t index_of(Precision p) { return static_cast<std::size_t>(p); }

std::string g3(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

// "position P·r_min, normal A°" of bounds b relative to the scene's smallest radius.
std::string describe(const ModeBounds& b, const PrecisionScene& s) {
  return "position " + g3(b.position / s.r_min) + "·r_min, normal " + g3(b.angle_deg) + "°";
}

// Why `mode` cannot serve the request (empty: it can).
std::string passed_over(Precision mode, const PrecisionScene& s, double position, double angle_deg) {
  if (!s.refusal[index_of(mode)].empty()) return "cannot run this scene (" + s.refusal[index_of(mode)] + ")";
  if (mode == Precision::fp32 && s.ellipsoids)  // (PrecisionScene::ellipsoids says why)
    return "bounds ellipsoid normals only by its solver tolerance (5e-4·κ rad for axis ratio κ)";
  const ModeBounds b = mode_bounds(mode, s);
  if (b.position <= position && b.angle_deg <= angle_deg) return {};
  return "gives " + describe(b, s) + " here";
}

}  // namespace

PrecisionScene precision_scene(const Bounds& global, bool ellipsoids, double cell_size, CellChoice choice) {
  PrecisionScene s;
  s.ellipsoids = ellipsoids;
  s.r_min = global.r_min;
  s.r_max = global.r_max;
  const double lo[3] = {global.lo.x, global.lo.y, global.lo.z},
               hi[3] = {global.hi.x, global.hi.y, global.hi.z};
  for (int k = 0; k < 3; ++k) {
    s.extent = std::max(s.extent, hi[k] - lo[k]);
    s.world_max = std::max({s.world_max, std::abs(lo[k]), std::abs(hi[k])});
  }
  for (Precision p : {Precision::fp32, Precision::fp64, Precision::mixed}) {
    try {  // what the frame stage and the engine's plan would refuse in this mode
      plan_grid(global, make_frame(global, cell_size, p, choice), p);
    } catch (const std::exception& e) {
      s.refusal[index_of(p)] = e.what();
      s.refusal_error[index_of(p)] = std::current_exception();
    }
  }
  return s;
}

ModeBounds mode_bounds(Precision mode, const PrecisionScene& s) {
  constexpr double kSqrt3 = 1.7320508075688772;  // per coordinate → the point's Euclidean error
  if (mode == Precision::fp32)
    return {kSqrt3 * (0.5 * ulp32(s.world_max) + 4 * kEps32 * (s.extent + s.r_max)) + s.r_max * kFp32Normal,
            kFp32Normal * kRadToDeg};
  return {kSqrt3 * (0.5 * ulp64(s.world_max) + 4 * kEps64 * s.r_max), 4 * kEps64 * kRadToDeg};
}

const std::array<Precision, 3>& cost_order(Backend backend) {
  // Both backends: fp32 <= mixed < fp64, the order their measured times take (BENCHMARKS.md §9, "The
  // cost order of --precision auto"; CUDA: §3, device-resident).
  static constexpr std::array<Precision, 3> cuda{Precision::fp32, Precision::mixed, Precision::fp64};
  static constexpr std::array<Precision, 3> cpu{Precision::fp32, Precision::mixed, Precision::fp64};
  return backend == Backend::cuda ? cuda : cpu;
}

PrecisionChoice choose_precision(const PrecisionScene& s, Backend backend, const Accuracy& accuracy) {
  const ModeBounds fp64 = mode_bounds(Precision::fp64, s);
  const double position = accuracy.position ? *accuracy.position * s.r_min : fp64.position;
  const double angle = accuracy.angle_deg.value_or(accuracy.position ? std::numeric_limits<double>::infinity()
                                                                     : fp64.angle_deg);
  const std::string request =
      accuracy.position ? "--accuracy " + g3(*accuracy.position) +
                              (accuracy.angle_deg ? "," + g3(*accuracy.angle_deg) + "°" : std::string())
                        : std::string("the default accuracy (fp64's)");
  std::string skipped;
  for (Precision mode : cost_order(backend)) {
    const std::string why = passed_over(mode, s, position, angle);
    if (!why.empty()) {
      skipped += std::string(skipped.empty() ? "" : "; ") + to_string(mode) + " " + why;
      continue;
    }
    PrecisionChoice c;
    c.mode = mode;
    c.reason = std::string("precision auto: ") + to_string(mode) + ", the cheapest on " + to_string(backend) +
               " that meets " + request + ": here " + describe(mode_bounds(mode, s), s);
    if (!skipped.empty()) c.reason += " (passed over: " + skipped + ")";
    return c;
  }
  const std::size_t fp64_index = index_of(Precision::fp64);
  if (s.refusal_error[fp64_index] &&
      std::all_of(s.refusal.begin(), s.refusal.end(), [](const std::string& r) { return !r.empty(); }))
    std::rethrow_exception(s.refusal_error[fp64_index]);
  throw InputError("no precision mode meets " + request + " for this scene (|x| up to " + g3(s.world_max) +
                   ", extent " + g3(s.extent) + ", radii " + g3(s.r_min) + " … " + g3(s.r_max) +
                   "): " + skipped + "; ask for at least what fp64 gives");
}

}  // namespace cg
