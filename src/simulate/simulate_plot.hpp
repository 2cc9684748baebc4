#pragma once
// The plots at the end of contactgrid simulate: energy (kinetic, potential, total) and contacts per
// step from log.csv, and a side view (x, z) of the final state as discs of the bodies' sizes, as PNG
// and SVG (gnuplot, as bench plots; skipped with a note without gnuplot).
#include <string>

#include "dem.hpp"

namespace cg {
// <prefix>.png and <prefix>.svg from the run's log.csv. Returns false (and says so unless quiet)
// when gnuplot is missing or fails; the run itself is unaffected.
bool plot_run_log(const std::string& log_csv, const std::string& prefix, bool quiet);
// <prefix>.png and <prefix>.svg: the bodies seen along y (discs of radius r, or an ellipsoid's mean
// semi-axis), from a table <prefix>.dat written beside them.
bool plot_final_state(const DemBodies& bodies, const std::string& prefix, bool quiet);
}  // namespace cg
