// Command-line parsing. Every option is validated here, before any file is read or any rank talks.
#include "cli/cli.hpp"

#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <vector>

#include "cli/commands.hpp"
#include "io/size_text.hpp"
#include "io/temp_output.hpp"
#include "io/xdmf.hpp"
#include "run/pipeline.hpp"
#include "simulate/simulate.hpp"
#if defined(CONTACTGRID_HAVE_BULLET)
#include "bench/bench.hpp"
#include "validate/validate.hpp"
#endif
#include "bench/broad_bench.hpp"
#include "session.hpp"
#include "study/study.hpp"
#include "study/study_families.hpp"

namespace cg {
namespace {

const std::map<std::string, Backend> k_backends{
    {"cpu", Backend::cpu}, {"cuda", Backend::cuda}, {"auto", Backend::automatic}};
#if defined(CONTACTGRID_HAVE_BULLET)
const std::map<std::string, BenchKind> k_bench_kinds{
    {"spheres", BenchKind::spheres}, {"ellipsoids", BenchKind::ellipsoids}, {"mixed", BenchKind::mixed}};
#endif
const std::map<std::string, Precision> k_precisions{
    {"fp32", Precision::fp32}, {"fp64", Precision::fp64}, {"mixed", Precision::mixed}};
const std::map<std::string, Fields> k_fields{{"basic", Fields::basic}, {"full", Fields::full}};
const std::map<std::string, BroadPhase> k_broad_phases{{"auto", BroadPhase::automatic},
                                                       {"grid", BroadPhase::grid},
                                                       {"levels", BroadPhase::levels},
                                                       {"sweep", BroadPhase::sweep},
                                                       {"brute", BroadPhase::brute}};
const std::map<std::string, SlabAxis> k_axes{
    {"auto", SlabAxis::automatic}, {"x", SlabAxis::x}, {"y", SlabAxis::y}, {"z", SlabAxis::z}};
const std::map<std::string, Balance> k_balances{{"count", Balance::count}, {"width", Balance::width}};
const std::map<std::string, SceneRead> k_reads{
    {"auto", SceneRead::automatic}, {"own", SceneRead::own_rows}, {"all", SceneRead::all_rows}};
const std::map<std::string, ContactOutput> k_writes{{"gather", ContactOutput::gather},
                                                    {"ranks", ContactOutput::ranks}};

// An enum option by name: the names are what --help and the error of a wrong word show (CLI11's
// CheckedTransformer shows the enum's internal numbers too). The word becomes the enum's number for
// CLI11 to store.
template <class E>
CLI::Validator enum_names(const std::map<std::string, E>& names) {
  std::string list;
  for (const auto& entry : names) list += (list.empty() ? "" : "|") + entry.first;
  return CLI::Validator(
      [names, list](std::string& word) -> std::string {
        const auto it = names.find(word);
        if (it == names.end()) return "'" + word + "' is not one of " + list;
        word = std::to_string(static_cast<long long>(it->second));
        return {};
      },
      list);
}

}  // namespace

std::optional<double> positive_number(const std::string& word) {
  std::size_t used = 0;
  double x = 0;
  try {
    x = std::stod(word, &used);
  } catch (const std::exception&) {
    return std::nullopt;
  }
  if (used != word.size() || !(x > 0) || !std::isfinite(x)) return std::nullopt;
  return x;
}

Accuracy parse_accuracy(const std::string& text) {
  const std::size_t comma = text.find(',');
  auto number = [&](const std::string& word, const char* what) {
    const std::optional<double> v = positive_number(word);
    if (!v) throw UsageError("--accuracy " + text + ": " + what + " '" + word + "' is not a number > 0");
    return *v;
  };
  Accuracy a;
  a.position = number(text.substr(0, comma), "the position error (relative to the smallest radius)");
  if (comma != std::string::npos) a.angle_deg = number(text.substr(comma + 1), "the normal angle (degrees)");
  return a;
}

namespace {

// One subcommand: its options, defined on the app (their values live as long as `run`), and what
// runs once they are parsed.
struct Subcommand {
  CLI::App* app = nullptr;
  std::function<int(Session&)> run;
};

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
       "would be crowded (and on CUDA for 2^21+ bodies of one size class without a skin), else grid; the "
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

// study: speed against accuracy of the precision modes (rank 0).
Subcommand add_study(CLI::App& app) {
  struct Args {
    StudyOptions options;
    std::vector<std::string> backends;
  };
  const auto args = std::make_shared<Args>();
  StudyOptions& study = args->options;
  std::vector<std::string> family_names;
  for (const auto& f : study_families()) family_names.push_back(f.name);
  auto* st = app.add_subcommand(
      "study",
      "Speed vs accuracy of each precision mode on adversarial scene families, against the exact "
      "(long-double) reference: table, CSV, SVG plot; no Bullet needed");
  st->add_option("--families", study.families, "Families to run (default: all)")
      ->delimiter(',')
      ->check(CLI::IsMember(family_names));
  st->add_option("--modes", study.modes, "Precision modes to run (default: all)")
      ->delimiter(',')
      ->check(CLI::IsMember(study_mode_names()));
  st->add_option("--backends", args->backends, "cpu, cuda (default: cpu, and cuda when a GPU is present)")
      ->delimiter(',')
      ->check(CLI::IsMember({"cpu", "cuda"}));
  st->add_option("--tolerances", study.tolerances,
                 "Ellipsoid solver tolerances (relative to the bodies' size; 0: the mode's default)")
      ->delimiter(',')
      ->capture_default_str();
  st->add_option("--scale", study.scale, "Family sizes × scale (1: ~1-2 min on 2 CPU cores)")
      ->check(CLI::Range(1e-6, 1e4))
      ->capture_default_str();
  st->add_option("--repetitions", study.repetitions, "Time = median of this many detect calls")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  st->add_option("--seed", study.seed, "Scene seed")->capture_default_str();
  st->add_option("--threads", study.threads, "CPU backend threads (0: all cores)")
      ->check(CLI::NonNegativeNumber);
  st->add_option("--csv", study.csv, "Write the rows as CSV");
  st->add_option("--svg", study.svg, "Write the time-vs-error plot (Pareto front) as SVG");

  return {st, [args](Session& session) {
            if (session.rank() != 0) return 0;
            for (const auto& name : args->backends)
              args->options.backends.push_back(name == "cuda" ? Backend::cuda : Backend::cpu);
            run_study(args->options, std::cout, std::cerr);
            return 0;
          }};
}

// bench-broad: the broad phases' timings (rank 0).
Subcommand add_bench_broad(CLI::App& app) {
  const auto args = std::make_shared<BroadBenchOptions>();
  auto* bbc = app.add_subcommand(
      "bench-broad",
      "Timing of the broad phases (grid, levels, sweep, brute, auto) x scene families x N on one backend: "
      "table and CSV; no Bullet needed");
  bbc->add_option("--families", args->families, "Families to run (default: all)")
      ->delimiter(',')
      ->check(CLI::IsMember(broad_bench_families()));
  bbc->add_option("--broad-phases", args->phases, "Broad phases to time (default: all; auto among them)")
      ->delimiter(',')
      ->transform(enum_names(k_broad_phases));
  bbc->add_option("--lo", args->lo, "First N = 2^lo")->capture_default_str();
  bbc->add_option("--hi", args->hi, "Last N = 2^hi")->capture_default_str();
  bbc->add_option("--step", args->step, "log2 N step")->check(CLI::PositiveNumber)->capture_default_str();
  bbc->add_option("--backend", args->backend, "Backend")
      ->transform(enum_names(std::map<std::string, Backend>{{"cpu", Backend::cpu}, {"cuda", Backend::cuda}}))
      ->default_str("cpu");
  bbc->add_option("--precision", args->precision, "Precision mode (docs/PRECISION.md)")
      ->transform(enum_names(k_precisions))
      ->default_str("fp64");
  bbc->add_option("--repetitions", args->repetitions, "Time = median of this many warm detections")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  bbc->add_option("--threads", args->threads, "CPU backend threads (0: all cores)")
      ->check(CLI::NonNegativeNumber);
  bbc->add_option("--brute-hi", args->brute_hi, "brute runs while N <= 2^brute-hi")->capture_default_str();
  bbc->add_option("--sweep-hi", args->sweep_hi, "sweep runs while N <= 2^sweep-hi")->capture_default_str();
  bbc->add_option("--budget", args->budget_s,
                  "Seconds: a broad phase slower than this at some N is not run at larger N of the family")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  bbc->add_option("--limit", args->limit_s,
                  "Seconds: a broad phase whose warm-up and repetitions at some N are predicted (from its "
                  "times at smaller N) to take longer is skipped, its prediction shown as >t; 0: none")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  bbc->add_option("--seed", args->seed, "Scene seed")->capture_default_str();
  bbc->add_flag("--cpu-time", args->cpu_time,
                "Time the process's CPU time, not the wall clock (CPU backend on a shared machine; with "
                "--threads 1 the work itself)");
  bbc->add_flag("--stage-times", args->stage_times,
                "Under each row, every broad phase's stage times (ms, its last repetition), levels, entries, "
                "pair tests and candidates");
  bbc->add_flag("--estimate", args->estimate,
                "Make the pair estimate before each pair stage, as detect does (its cost in the times)");
  bbc->add_option("--csv", args->csv, "Also write the runs as CSV");
  return {bbc, [args](Session& session) {
            if (session.rank() != 0) return 0;
            run_broad_bench(*args, std::cout);
            return 0;
          }};
}

#if defined(CONTACTGRID_HAVE_BULLET)
// validate: a contact file against Bullet (rank 0).
Subcommand add_validate(CLI::App& app) {
  struct Args {
    std::string scene, contacts, bullet = "auto";
    ValidateOptions options;
  };
  const auto args = std::make_shared<Args>();
  ValidateOptions& val = args->options;
  auto* v = app.add_subcommand(
      "validate", "Compare a contacts file with Bullet 3.24 (docs/FORMAT.md §4); PASS exits 0, FAIL 1");
  v->add_option("scene", args->scene, "Scene file (.h5)")->required();
  v->add_option("contacts", args->contacts, "Contacts file (.h5) written by detect")->required();
  v->add_option("--pos-eps", val.pos_eps,
                "Largest position error allowed, as a fraction of L, the pair's larger bounding radius (also "
                "the largest distance error of pairs with an ellipsoid)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  v->add_option_function<double>(
       "--pos-abs", [&val](double x) { val.pos_abs = x; },
       "Largest position error allowed as a length (scene units), instead of --pos-eps")
      ->check(CLI::PositiveNumber);
  v->add_option("--angle-deg", val.angle_deg, "Largest angle between normals allowed (degrees)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  v->add_option("--bullet-precision,--bullet", args->bullet,
                "auto | double | float: Bullet build to compare with; auto: float for scenes with ellipsoids "
                "(double Bullet's EPA is degenerate on many ellipsoid pairs), double otherwise (its sphere "
                "contacts are "
                "exact formulas in double)")
      ->check(CLI::IsMember({"auto", "double", "float"}))
      ->capture_default_str();
  v->add_option("--shallow", val.shallow,
                "Ellipsoid pairs only we report, judged correct and shallower than this x L, are shallow "
                "Bullet misses (accepted; a quarter of Bullet's ellipsoid margin in its frame)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  v->add_option_function<double>(
       "--shallow-abs", [&val](double x) { val.shallow_abs = x; },
       "The shallow threshold as a length (scene units), instead of --shallow")
      ->check(CLI::NonNegativeNumber);
  v->add_option_function<std::string>(
       "--memory", [&val](const std::string& t) { val.memory_limit = parse_memory(t); },
       "Peak memory to stay under (e.g. 8G, 512M): Bullet runs on the scene in pieces that fit; "
       "default: 4G or half the machine's memory, whichever is smaller")
      ->default_str(fmt::format("{:.3g}G", double(default_memory_limit()) / double(1 << 30)));
  v->add_option("--sample", val.sample,
                "Validate K random sub-boxes instead of the whole scene (large scenes): each about 4000 "
                "bodies, or fewer where they touch more (about 4000 contacts a box)");
  v->add_option("--seed", val.seed, "Seed of the sub-box choice")->capture_default_str();

  return {v, [args](Session& session) {
            if (session.rank() != 0) return 0;
            args->options.bullet = parse_bullet_precision(args->bullet);
            args->options.progress = true;
            const ValidateReport report = validate_files(args->scene, args->contacts, args->options);
            fmt::print("{}", report.text());
            return report.pass ? 0 : 1;
          }};
}

// bench: the engine against Bullet over N (rank 0).
Subcommand add_bench(CLI::App& app) {
  struct Args {
    BenchOptions options;
    std::vector<std::string> backends;
    bool no_plot = false;
  };
  const auto args = std::make_shared<Args>();
  BenchOptions& bench = args->options;
  auto* b =
      app.add_subcommand("bench", "Timing study: engine vs Bullet for N = 2^lo … 2^hi (table, CSV, plots)");
  b->add_option("--kind", bench.kind,
                "spheres (double Bullet, warm step) | ellipsoids | mixed (float Bullet with the exact "
                "ellipsoid support, from scratch; narrow-phase counters)")
      ->transform(enum_names(k_bench_kinds))
      ->default_str("spheres");
  b->add_option("--max-aspect", bench.max_aspect,
                "ellipsoids, mixed: semi-axes U[1/K, 1], so no body is longer than 1:K (issue #12: 4)")
      ->check(CLI::Range(1.0, 1000.0))
      ->capture_default_str();
  b->add_option("--ellipsoid-fraction", bench.ellipsoid_fraction, "mixed: share of ellipsoids, in [0, 1]")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  b->add_option("--contacts-per-body", bench.contacts_per_body,
                "The generator's density (bounding spheres: for ellipsoids the candidates per body)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  b->add_option("--lo", bench.lo, "First N = 2^lo")->capture_default_str();
  b->add_option("--bullet-hi", bench.bullet_hi, "Bullet runs while N <= 2^bullet-hi")->capture_default_str();
  b->add_option("--engine-hi", bench.engine_hi, "The engine runs while N <= 2^engine-hi")
      ->capture_default_str();
  b->add_option("--repetitions", bench.repetitions, "Engine time = median of this many warm runs")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  b->add_option("--backend", args->backends, "cpu | cuda (repeatable; default: cpu, and cuda when present)")
      ->check(CLI::IsMember({"cpu", "cuda"}));
  b->add_option("--threads", bench.threads, "CPU backend threads (0: all cores)");
  b->add_option("--precision", bench.precision, "fp32 | fp64 | mixed: the engine's precision mode")
      ->transform(enum_names(k_precisions))
      ->default_str("fp64");
  b->add_option("--seed", bench.seed, "Scene seed")->capture_default_str();
  b->add_option("--csv", bench.csv, "CSV output")->capture_default_str();
  b->add_option("--plot-prefix", bench.plot_prefix, "Plot file prefix (PNG and SVG); default: the CSV name");
  b->add_flag("--no-plot", args->no_plot, "Do not run gnuplot");
  return {b, [args](Session& session) {
            if (session.rank() != 0) return 0;
            for (const auto& name : args->backends)
              args->options.backends.push_back(name == "cuda" ? Backend::cuda : Backend::cpu);
            args->options.plot = !args->no_plot;
            run_bench(args->options);
            return 0;
          }};
}
#endif

}  // namespace

int run_cli(int argc, char** argv, Session& session) {
  CLI::App app{
      "contactgrid: every touching or overlapping pair of spheres and ellipsoids, with Bullet's contact\n"
      "data. Le Grand's uniform grid on a CPU or CUDA backend; MPI slabs under mpirun.\n"
      "Files and conventions: docs/FORMAT.md; commands and exit codes: docs/USAGE.md."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "contactgrid " CONTACTGRID_VERSION);
  std::vector<Subcommand> commands{add_generate(app), add_detect(app), add_simulate(app),
                                   add_compare(app),  add_study(app),  add_bench_broad(app)};
#if defined(CONTACTGRID_HAVE_BULLET)
  commands.push_back(add_validate(app));
  commands.push_back(add_bench(app));
#endif

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;
  }
  for (const Subcommand& command : commands)
    if (command.app->parsed()) return command.run(session);
  return 2;
}

}  // namespace cg
