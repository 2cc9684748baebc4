#pragma once
// The contactgrid command line (CLI11): generate, detect, compare, study, validate, bench.
#include <optional>
#include <string>

#include "precision_choice.hpp"

namespace cg {
// `word` as a finite number > 0, the whole word (no trailing characters); nothing otherwise.
std::optional<double> positive_number(const std::string& word);

// --accuracy "POS" or "POS,ANGLE" (both finite > 0; ANGLE in degrees); throws UsageError naming it.
Accuracy parse_accuracy(const std::string& text);

// Parses argv and runs the command. Returns the exit code; throws cg::Error for the caller (main)
// to turn into a message and its exit code.
class Session;
int run_cli(int argc, char** argv, Session& session);
}  // namespace cg
