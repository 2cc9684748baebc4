#pragma once
// The subcommands of the command line (cli.cpp: run_cli), each defined by an add_<command> of its
// family's file: scene_commands.cpp (generate, detect, compare), simulate_command.cpp (simulate),
// study_commands.cpp (study, bench-broad, validate, bench). The words of their options: option_words.hpp.
#include <CLI/CLI.hpp>
#include <functional>
#include <string>

namespace cg {
class Session;
}

namespace cg::cli {

// One subcommand: its options, defined on the app (their values live as long as `run`), and what
// runs once they are parsed.
struct Subcommand {
  CLI::App* app = nullptr;
  std::function<int(Session&)> run;
};

Subcommand add_generate(CLI::App& app);
Subcommand add_detect(CLI::App& app);
Subcommand add_compare(CLI::App& app);
Subcommand add_simulate(CLI::App& app);
Subcommand add_study(CLI::App& app);
Subcommand add_bench_broad(CLI::App& app);
#if defined(CONTACTGRID_HAVE_BULLET)
Subcommand add_validate(CLI::App& app);
Subcommand add_bench(CLI::App& app);
#endif

}  // namespace cg::cli
