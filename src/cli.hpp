#pragma once
// The contactgrid command line (CLI11): generate, detect, compare, study, validate, bench.
namespace cg {
// Parses argv and runs the command. Returns the exit code; throws cg::Error for the caller (main)
// to turn into a message and its exit code.
class Session;
int run_cli(int argc, char** argv, Session& session);
}  // namespace cg
