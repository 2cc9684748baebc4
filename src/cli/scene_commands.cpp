// The scene and contact commands of the command line: generate, detect, compare (subcommands.hpp).
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

namespace cg::cli {

// generate: a seeded scene file (rank 0 writes it).
Subcommand add_generate(CLI::App& app) {
  struct Args {
    GenerateOptions options;
    std::string output;
    bool quiet = false;
    bool xdmf = false;
    std::vector<double> offset;
    double ratio = 10;
    double max_aspect = 0;
    long long count = 0;  // -n, signed: -n -3 is named as typed
  };
  const auto args = std::make_shared<Args>();
  GenerateOptions& gen = args->options;
  args->count = static_cast<long long>(gen.count);
  auto* g = app.add_subcommand("generate", "Make a seeded, reproducible scene (docs/FORMAT.md §1 HDF5)");
  g->add_option("output", args->output, "Scene file to write (.h5)")->required();
  g->add_option(
       "--kind", gen.kind,
       "uniform | polydisperse | ellipsoids (semi-axes uniform in [Rlow, Rhigh], random orientations) "
       "| mixed (spheres then ellipsoids) | bimodal (radii Rlow and Rhigh, --large-fraction of the volume "
       "in the large) | intruders (--intruders bodies of Rhigh among grains of Rlow at the uniform "
       "scene's density) | pour, pour-ellipsoids (a column of bodies above a floor in an open box, ready "
       "for simulate, which takes its walls from the file)")
      ->check(CLI::IsMember({"uniform", "polydisperse", "ellipsoids", "mixed", "bimodal", "intruders", "pour",
                             "pour-ellipsoids"}))
      ->capture_default_str();
  g->add_option("--ellipsoid-fraction", gen.ellipsoid_fraction, "mixed: share F of ellipsoids, in [0, 1]")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  g->add_option("--large-fraction", gen.large_fraction,
                "bimodal: share of the bodies' volume in the large ones (radius Rhigh), in [0, 1]")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  g->add_option("--intruders", gen.intruders, "intruders: how many large bodies (radius Rhigh), 1 … count")
      ->check(CLI::Range(std::uint64_t(1), std::uint64_t(1) << 28))
      ->capture_default_str();
  g->add_option("--pour-spacing", gen.pour_spacing,
                "pour, pour-ellipsoids: lattice spacing in units of Rhigh (2.1: apart; below 2: every body "
                "presses on its six neighbours, a settled pack's contact count)")
      ->check(CLI::Range(1.5, 10.0))
      ->capture_default_str();
  // (checked when it runs: CLI11 names an option by its long name, and the user typed -n)
  g->add_option("-n,--count", args->count, "Number of bodies, 1 … 2^28")->capture_default_str();
  g->add_option("--seed", gen.seed, "Random seed")->capture_default_str();
  auto* rlow_opt =
      g->add_option("--rlow", gen.radius_low, "Smallest radius Rlow (length units)")->capture_default_str();
  g->add_option("--ratio", args->ratio,
                "polydisperse, bimodal, intruders: Rhigh / Rlow when --rlow is not given (up to 1000)")
      ->check(CLI::Range(1.0, 1000.0))
      ->capture_default_str();
  g->add_option("--rhigh", gen.radius_high, "Largest radius Rhigh (length units)")->capture_default_str();
  auto* aspect_opt =
      g->add_option("--max-aspect", args->max_aspect,
                    "ellipsoids, mixed: semi-axes U[Rhigh/K, Rhigh], no body longer than 1:K (sets Rlow)")
          ->check(CLI::Range(1.0, 1000.0))
          ->excludes(rlow_opt);
  g->add_option("--contacts-per-body", gen.contacts_per_body,
                "Target mean contacts per sphere; sets the box edge (course: 0.4)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  g->add_option("--offset", args->offset, "Translate the scene by (x, y, z)")->expected(3);
  g->add_flag("-q,--quiet", args->quiet, "No summary");
  g->add_flag("--xdmf", args->xdmf,
              "Also write XDMF beside the scene for ParaView (<scene>.spheres.xmf, ...)");

  return {
      g, [args, rlow_opt, aspect_opt](Session& session) {
        if (args->count < 1 || args->count > (1LL << 28))
          throw UsageError(
              fmt::format("-n (--count) {}: the number of bodies must be 1 … 2^28", args->count));
        if (session.rank() != 0) return 0;  // one writer
        GenerateOptions& options = args->options;
        options.count = static_cast<std::uint64_t>(args->count);
        const std::vector<double>& offset = args->offset;
        if (!offset.empty()) options.offset = {offset[0], offset[1], offset[2]};
        if ((options.kind == "polydisperse" || options.kind == "bimodal" || options.kind == "intruders") &&
            rlow_opt->count() == 0)
          options.radius_low = options.radius_high / args->ratio;
        if (aspect_opt->count() > 0) {
          if (options.kind != "ellipsoids" && options.kind != "mixed" && options.kind != "pour-ellipsoids")
            throw UsageError("--max-aspect applies to --kind ellipsoids, mixed or pour-ellipsoids");
          options.radius_low = options.radius_high / args->max_aspect;
        }
        const int code = run_generate(args->output, options, args->quiet);
        if (args->xdmf) {  // the scene and its XDMF files appear all or none
          FinishedOutputs done;
          done.add(args->output);
          write_xdmf(args->output, "", xdmf_base(args->output));
          done.keep();
        }
        return code;
      }};
}

// detect: every contact of a scene, over all ranks (run/pipeline.hpp).
Subcommand add_detect(CLI::App& app) {
  const auto args = std::make_shared<DetectCommand>();
  DetectCommand& det = *args;
  auto* d =
      app.add_subcommand("detect", "Every contact of a scene (docs/FORMAT.md §2/§3), sorted by (id_a, id_b)");
  d->add_option("scene", det.input, "Scene file (.h5)")
      ->required();  // existence is checked by the reader (exit 3, names the file)
  d->add_option("-o,--output", det.output,
                "Contacts file to write (.h5); its directory must exist and be writable (checked first)")
      ->required();
  d->add_option("--backend", det.backend, "cpu | cuda | auto (cuda when a GPU is present)")
      ->transform(enum_names(k_backends))
      ->default_str("auto");
  d->add_option_function<std::string>(
       "--precision",
       [&det](const std::string& v) {
         if (v == "auto") {
           det.precision.reset();
           return;
         }
         const auto it = k_precisions.find(v);
         if (it == k_precisions.end())
           throw CLI::ValidationError("--precision", "'" + v + "' is not auto, fp32, fp64 or mixed");
         det.precision = it->second;
       },
       "auto | fp32 | fp64 | mixed: auto (default) picks the cheapest mode whose documented bounds meet "
       "--accuracy for this scene (default accuracy: fp64's, so fp64's answers); fp32 and fp64 run every "
       "stage and write their real type; mixed runs the broad phase in fp32 and the narrow phase in fp64 "
       "from the world coordinates (float64 output, fp64's contacts); docs/PRECISION.md")
      ->default_str("auto");
  d->add_option_function<std::string>(
      "--accuracy",
      [&det](const std::string& v) {
        try {
          det.accuracy = parse_accuracy(v);
        } catch (const UsageError& e) {
          throw CLI::ValidationError("--accuracy", e.what());
        }
      },
      "POS[,ANGLE] for --precision auto: the position error accepted, relative to the smallest radius, "
      "and the normal angle in degrees (default: what fp64 gives)");
  d->add_option("--fields", det.fields, "basic | full (adds local points and friction directions)")
      ->transform(enum_names(k_fields))
      ->default_str("basic");
  d->add_option_function<std::string>(
       "--cell-size",
       [&det](const std::string& v) {
         if (v == "auto" || v == "min") {
           det.cell_size = 0;
           det.cell_choice = v == "auto" ? CellChoice::tuned : CellChoice::smallest;
           return;
         }
         const std::optional<double> x = positive_number(v);
         if (!x) throw CLI::ValidationError("--cell-size", "'" + v + "' is not auto, min or a length > 0");
         det.cell_size = *x;
       },
       "Grid cell edge: auto (the edge a cost model of the sort and pair stages picks, 1-3x the "
       "smallest), min (the largest diameter + rounding margin, Le Grand's choice) or a length")
      ->default_str("auto");
  d->add_option(
       "--broad-phase", det.broad_phase,
       "auto | grid (Le Grand's uniform grid) | levels (a grid per size class: any size "
       "distribution) | sweep (Baraff's sort and sweep) | brute (every pair): auto picks brute for "
       "a few dozen bodies, levels where the largest radius exceeds 4x the mean and the grid's cells "
       "would be crowded (and on CUDA for 2^21+ bodies of one size class without a skin, below 1.75 "
       "expected contacts a body), else grid; the "
       "contacts are the same bits whichever runs")
      ->transform(enum_names(k_broad_phases))
      ->default_str("auto");
  d->add_option("--solver-tolerance", det.solver_tolerance,
                "Ellipsoid solver: Newton stops when the tangential gradient is <= this x the pair's size "
                "(0: the mode's default, fp32 2e-5, fp64 1e-11); larger is faster and less accurate")
      ->check(CLI::NonNegativeNumber)
      ->default_str("0");
  d->add_option("--solver-iterations", det.solver_iterations,
                "Ellipsoid solver: evaluations of f per Newton start, at most (0: the default, 40); a pair "
                "that does not converge takes the safety net and is counted as unconverged")
      ->check(CLI::NonNegativeNumber)
      ->default_str("0");
  d->add_option("--csv", det.csv, "Also write the contacts as CSV (for small results)");
  d->add_option("--max-pair-tests", det.max_pair_tests,
                "Refuse a scene whose pair stage would test more than N pairs on a rank (estimated from "
                "the cells' occupancy before the pair stage; exit code 9; 0: no limit)")
      ->check(CLI::NonNegativeNumber)
      ->default_str("0");
  d->add_option_function<std::string>(
      "--memory-limit", [&det](const std::string& t) { det.memory_limit = parse_size(t, "--memory-limit"); },
      "Device memory a rank's detection may use (e.g. 4G, 512M): contacts that do not fit are computed "
      "in pieces (slabs of the scene) with the same result; a scene that does not fit even in the smallest "
      "piece is refused (exit code 7). Default: the device's memory, in one piece");
  d->add_option("--threads", det.threads, "CPU backend threads (0: all cores)")
      ->check(CLI::NonNegativeNumber);
  d->add_option("--axis", det.axis, "MPI slab axis: auto (largest extent) | x | y | z")
      ->transform(enum_names(k_axes))
      ->default_str("auto");
  d->add_option("--balance", det.balance, "MPI slab bounds: count (equal bodies) | width (equal widths)")
      ->transform(enum_names(k_balances))
      ->default_str("count");
  d->add_option("--read", det.read,
                "MPI scene read: auto (all when every rank is on one node, else own) | own (each rank its "
                "rows, bodies then move to their owners) | all (every rank reads every row and keeps its "
                "own bodies and ghosts: no body moves)")
      ->transform(enum_names(k_reads))
      ->default_str("auto");
  d->add_option("--write", det.write,
                "MPI output: gather (rank 0 gathers, deduplicates and writes the sorted contacts) | ranks "
                "(each rank merges the contacts of its id_a range and writes them into the same file)")
      ->transform(enum_names(k_writes))
      ->default_str("gather");
  auto* steps =
      d->add_option("--steps", det.steps,
                    "Then measure N resident steps: each rank keeps its bodies on its GPU (or in memory), "
                    "refreshes its ghosts through MPI and detects again, contacts left in place (checked "
                    "against the file's count); prints the median step")
          ->check(CLI::NonNegativeNumber);
  d->add_option_function<std::string>(
       "--skin",
       [&det](const std::string& v) {
         det.skin_auto = v == "auto";
         if (det.skin_auto) return;
         const std::optional<double> x = v == "0" ? std::optional<double>(0.0) : positive_number(v);
         if (!x) throw CLI::ValidationError("--skin", "'" + v + "' is not auto or a length >= 0");
         det.skin = *x;
       },
       "Verlet skin: a world length (default 0) or auto. The engines keep their candidate pairs across "
       "the --steps and reuse them while the bodies moved less than skin/2 (stage skin in the step "
       "times); auto picks the skin from the observed motion for the lowest mean step; contacts unchanged")
      ->default_str("0");
  d->add_option("--spin", det.spin,
                "Radians per step (default 0): in the --steps every ellipsoid turns by W·step about a fixed "
                "axis drawn from its id, and the ghosts' orientations refresh through MPI; the last step's "
                "contacts are then checked against the turned bodies detected from scratch")
      ->needs(steps);
  d->add_option("--drift", det.drift,
                "World length per step (default 0): in the --steps every body's centre moves by V·step along "
                "a unit direction drawn from its id, so bodies cross the slabs (migrating between ranks) and "
                "leave the box; -o then receives the last step's contacts")
      ->needs(steps);
  d->add_option("--final-scene", det.final_scene,
                "With --steps: write the last step's bodies as a scene file (a plain detect of it gives the "
                "last step's contacts)")
      ->needs(steps);
  auto* det_quiet = d->add_flag("-q,--quiet", det.quiet, "No summary");
  d->add_flag("-v,--verbose", det.verbose,
              "Also the run's info lines: the merge of the ranks' contacts, with the duplicates removed "
              "(expected 0; removed duplicates are reported without -v too)")
      ->excludes(det_quiet);
  d->add_flag("--xdmf", det.xdmf,
              "Also write XDMF beside the contacts for ParaView: <output>.xmf (contacts) and the bodies' "
              "<output>.spheres.xmf, <output>.ellipsoids.xmf");

  return {d, [args](Session& session) {
            const int code = run_detect(*args, session);
            if (args->xdmf && session.rank() == 0) {  // the outputs appear all or none
              FinishedOutputs done;
              done.add(args->output);
              if (!args->csv.empty()) done.add(args->csv);
              write_xdmf(args->input, args->output, xdmf_base(args->output));
              done.keep();
            }
            return code;
          }};
}

// compare: are two contact files' /contacts byte-identical (rank 0)?
Subcommand add_compare(CLI::App& app) {
  struct Args {
    std::string a, b;
  };
  const auto args = std::make_shared<Args>();
  auto* c = app.add_subcommand(
      "compare", "Are the /contacts datasets of two contact files byte-identical? (0 yes, 1 no)");
  c->add_option("a", args->a, "Contacts file")->required();
  c->add_option("b", args->b, "Contacts file")->required();

  return {c, [args](Session& session) { return session.rank() == 0 ? run_compare(args->a, args->b) : 0; }};
}

}  // namespace cg::cli
