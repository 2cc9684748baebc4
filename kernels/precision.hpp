#pragma once
// The precision modes of the engine, and the one conversion from its real types to the mode.
// g++-safe public header (part of engine.hpp through grid_plan.hpp).
#include <type_traits>

namespace cg {

// The precision modes (docs/PRECISION.md): fp32 and fp64 run every stage in one real
// type; mixed runs the broad phase (pack … order) in float and the narrow phase in double from the
// world coordinates, with float64 output (Engine<double> with EngineOptions::fp32_broad_phase).
enum class Precision { fp32, fp64, mixed };
constexpr const char* to_string(Precision p) {
  switch (p) {
    case Precision::fp32:
      return "fp32";
    case Precision::fp64:
      return "fp64";
    case Precision::mixed:
      return "mixed";
  }
  return "?";
}

// The precision mode of the stage types Broad (pack … order) and Narrow (narrow, output): the one
// conversion from the templates to the enum.
template <class Broad, class Narrow = Broad>
constexpr Precision precision_of() {
  static_assert(std::is_same_v<Broad, float> || std::is_same_v<Broad, double>, "Real is float or double");
  static_assert(std::is_same_v<Narrow, double> || std::is_same_v<Broad, Narrow>,
                "no fp64 broad, fp32 narrow");
  return !std::is_same_v<Broad, Narrow> ? Precision::mixed
         : std::is_same_v<Broad, float> ? Precision::fp32
                                        : Precision::fp64;
}

// The real type of the broad phase's local coordinates is float (fp32, mixed).
constexpr bool float_broad_phase(Precision p) { return p != Precision::fp64; }

}  // namespace cg
