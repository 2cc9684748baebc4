// The simulate command of the command line (subcommands.hpp).
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <vector>

#include "cli/cli.hpp"
#include "cli/commands.hpp"
#include "cli/option_words.hpp"
#include "cli/subcommands.hpp"
#include "io/size_text.hpp"
#include "io/temp_output.hpp"
#include "io/xdmf.hpp"
#include "run/pipeline.hpp"
#include "session.hpp"
#include "simulate/simulate.hpp"

namespace cg::cli {

// simulate: granular dynamics of a scene (simulate/simulate.hpp).
Subcommand add_simulate(CLI::App& app) {
  struct Args {
    SimulateCommand command;
    std::vector<double> gravity;
  };
  const auto args = std::make_shared<Args>();
  SimulateCommand& sim = args->command;
  auto* sm = app.add_subcommand(
      "simulate",
      "Granular dynamics of a scene (Hertz-Mindlin, friction, walls, gravity): frames, contacts and a log "
      "in a run directory (docs/FORMAT.md §6)");
  sm->add_option("scene", sim.input, "Scene file (.h5), with velocities if it has them (docs/FORMAT.md §5)")
      ->required();
  sm->add_option("-o,--output", sim.output, "Run directory to create (must not exist or be empty)")
      ->required();
  sm->add_option("--steps", sim.steps, "Time steps to take")->capture_default_str();
  sm->add_option_function<std::string>(
        "--dt",
        [&sim = args->command](const std::string& v) {
          if (v == "auto") {
            sim.dt.reset();
            return;
          }
          const std::optional<double> x = positive_number(v);
          if (!x) throw CLI::ValidationError("--dt", "'" + v + "' is not auto or a time > 0");
          sim.dt = *x;
        },
        "Time step (s): auto (0.2 x the Rayleigh time of the smallest body, at most the Hertz contact time / "
        "40 "
        "at the fastest expected impact) or a time (warned when above twice auto, refused above the Rayleigh "
        "time)")
      ->default_str("auto");
  sm->add_option("--output-every", sim.output_every, "A frame every K steps (default: steps / 10)");
  sm->add_option("--log-every", sim.log_every, "A log.csv row every K steps (default: output-every / 10)");
  sm->add_option("--gravity", args->gravity, "Gravity GX GY GZ (default 0 0 -9.81)")->expected(3);
  sm->add_option(
      "--walls", sim.walls,
      "A wall (repeatable): plane:PX,PY,PZ,NX,NY,NZ | box:X0,Y0,Z0,X1,Y1,Z1 | open-box:X0,Y0,Z0,X1,Y1,Z1 "
      "(sides only) | cylinder:CX,CY,R | orifice:CX,CY,Z,H | hopper:CX,CY,R,Z,H (cylinder on a plate "
      "with a hole); default: the scene's simulate_walls (generate --kind pour)");
  sm->add_option("--young", sim.material.young, "Young's modulus E (Pa)")->capture_default_str();
  sm->add_option("--poisson", sim.material.poisson, "Poisson ratio")->capture_default_str();
  sm->add_option("--density", sim.material.density, "Density (kg/m^3)")->capture_default_str();
  sm->add_option("--restitution", sim.material.restitution, "Coefficient of restitution, (0, 1]")
      ->capture_default_str();
  sm->add_option("--friction", sim.material.friction, "Sliding friction coefficient")->capture_default_str();
  sm->add_option("--rolling-friction", sim.material.rolling_friction,
                 "Rolling friction coefficient (0: none)")
      ->capture_default_str();
  sm->add_flag("--stage-times", sim.stage_times,
               "Print where a step's time goes: each stage's mean ms a step (CUDA: events; the host waits "
               "for each step's end)");
  sm->add_flag("--write-contacts", sim.write_contacts,
               "Also write contacts_<step>.h5 with each frame (docs/FORMAT.md §2 with the history fields)");
  sm->add_option("--backend", sim.backend, "Backend of the contact detection and the dynamics")
      ->transform(enum_names(k_backends))
      ->default_str("auto");
  sm->add_option("--precision", sim.precision, "the contact detection's precision (dynamics: fp64)")
      ->transform(enum_names(k_precisions))
      ->default_str("fp64");
  sm->add_option_function<std::string>(
        "--skin",
        [&sim = args->command](const std::string& v) {
          if (v == "auto") {
            sim.skin.reset();
            return;
          }
          std::size_t used = 0;
          double x = -1;
          try {
            x = std::stod(v, &used);
          } catch (const std::exception&) {
          }
          if (used != v.size() || !(x >= 0) || !std::isfinite(x))
            throw CLI::ValidationError("--skin", "'" + v + "' is not auto or a length >= 0");
          sim.skin = x;
        },
        "Verlet skin of the contact detection: auto (a tenth of the smallest radius) or a length")
      ->default_str("auto");
  sm->add_option("--order", sim.order,
                 "The bodies' order in the run: cells (sorted by the cell of their centre, so a contact's "
                 "bodies lie near each other in memory: faster), file (the scene's), auto (cells, file "
                 "with --write-contacts); frames are written in the scene's order either way")
      ->transform(enum_names(
          std::map<std::string, SimulateCommand::Order>{{"auto", SimulateCommand::Order::automatic},
                                                        {"cells", SimulateCommand::Order::cells},
                                                        {"file", SimulateCommand::Order::file}}))
      ->default_str("auto");
  sm->add_option("--threads", sim.threads, "CPU backend threads (0: all cores)")
      ->check(CLI::NonNegativeNumber);
  sm->add_flag(
      "--plain-verlet", [&sim = args->command](std::int64_t) { sim.synchronized = false; },
      "Integrate with plain velocity Verlet instead of the synchronised one (for comparison)");
  sm->add_flag(
      "--no-plot", [&sim = args->command](std::int64_t) { sim.plots = false; },
      "Do not run gnuplot at the end");
  sm->add_flag("-q,--quiet", sim.quiet, "No summary");

  return {sm, [args](Session& session) {
            if (!args->gravity.empty())
              args->command.gravity = {args->gravity[0], args->gravity[1], args->gravity[2]};
            return run_simulate(args->command, session);
          }};
}

}  // namespace cg::cli
