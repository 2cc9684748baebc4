#pragma once
// Running a helper program (gnuplot for the plots of bench and simulate): where it is on PATH, and
// its exit status.
#include <string>
#include <vector>

namespace cg {
// The first executable `name` on PATH ("" when none).
std::string find_on_path(const std::string& name);
// Runs args[0] with args (no shell) and waits: its exit status, or -1 when it could not run.
int run_program(const std::vector<std::string>& args);
}  // namespace cg
