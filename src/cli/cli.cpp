// Command-line parsing. Every option is validated here, before any file is read or any rank talks.
#include "cli/cli.hpp"

#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <iostream>
#include <map>

#include "run/pipeline.hpp"
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

int run_cli(int argc, char** argv, Session& session) {
  CLI::App app{
      "contactgrid: every touching or overlapping pair of spheres, with Bullet's contact data.\n"
      "Le Grand's uniform grid on a CPU or CUDA backend; MPI slabs under mpirun."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "contactgrid " CONTACTGRID_VERSION);

  // generate
  GenerateOptions gen;
  std::string gen_out;
  bool gen_quiet = false;
  std::vector<double> offset;
  auto* g = app.add_subcommand("generate", "Make a seeded, reproducible scene (CONTRACT §1 HDF5)");
  g->add_option("output", gen_out, "Scene file to write (.h5)")->required();
  g->add_option(
       "--kind", gen.kind,
       "uniform | polydisperse | ellipsoids (semi-axes uniform in [Rlow, Rhigh], random orientations) "
       "| mixed (spheres then ellipsoids) | bimodal (radii Rlow and Rhigh, --large-fraction of the volume "
       "in the large) | intruders (--intruders bodies of Rhigh among grains of Rlow at the uniform "
       "scene's density)")
      ->check(CLI::IsMember({"uniform", "polydisperse", "ellipsoids", "mixed", "bimodal", "intruders"}))
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
  g->add_option("-n,--count", gen.count, "Number of bodies, 1 … 2^28")
      ->check(CLI::Range(std::uint64_t(1), std::uint64_t(1) << 28))
      ->capture_default_str();
  g->add_option("--seed", gen.seed, "Random seed")->capture_default_str();
  double gen_ratio = 10;
  auto* rlow_opt =
      g->add_option("--rlow", gen.radius_low, "Smallest radius Rlow (length units)")->capture_default_str();
  g->add_option("--ratio", gen_ratio,
                "polydisperse, bimodal, intruders: Rhigh / Rlow when --rlow is not given (up to 1000)")
      ->check(CLI::Range(1.0, 1000.0))
      ->capture_default_str();
  g->add_option("--rhigh", gen.radius_high, "Largest radius Rhigh (length units)")->capture_default_str();
  double gen_max_aspect = 0;
  auto* aspect_opt =
      g->add_option("--max-aspect", gen_max_aspect,
                    "ellipsoids, mixed: semi-axes U[Rhigh/K, Rhigh], no body longer than 1:K (sets Rlow)")
          ->check(CLI::Range(1.0, 1000.0))
          ->excludes(rlow_opt);
  g->add_option("--contacts-per-body", gen.contacts_per_body,
                "Target mean contacts per sphere; sets the box edge (course: 0.4)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  g->add_option("--offset", offset, "Translate the scene by (x, y, z)")->expected(3);
  g->add_flag("-q,--quiet", gen_quiet, "No summary");

  // detect
  DetectCommand det;
  auto* d = app.add_subcommand("detect", "Every contact of a scene (CONTRACT §2/§3), sorted by (id_a, id_b)");
  d->add_option("scene", det.input, "Scene file (.h5)")
      ->required();  // existence is checked by the reader (exit 3, names the file)
  d->add_option("-o,--output", det.output, "Contacts file to write (.h5)")->required();
  d->add_option("--backend", det.backend, "cpu | cuda | auto (cuda when a GPU is present)")
      ->transform(CLI::CheckedTransformer(k_backends))
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
       "from the world coordinates (float64 output, fp64's contacts); README 'Choosing a precision'")
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
      ->transform(CLI::CheckedTransformer(k_fields))
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
  d->add_option("--broad-phase", det.broad_phase,
                "auto | grid (Le Grand's uniform grid) | levels (a grid per size class: any size "
                "distribution) | sweep (Baraff's sort and sweep) | brute (every pair): auto picks brute for "
                "a few dozen bodies, levels where the largest radius exceeds 4x the mean, else grid; the "
                "contacts are the same bits whichever runs")
      ->transform(CLI::CheckedTransformer(k_broad_phases))
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
  d->add_option("--threads", det.threads, "CPU backend threads (0: all cores)")
      ->check(CLI::NonNegativeNumber);
  d->add_option("--axis", det.axis, "MPI slab axis: auto (largest extent) | x | y | z")
      ->transform(CLI::CheckedTransformer(k_axes))
      ->default_str("auto");
  d->add_option("--balance", det.balance, "MPI slab bounds: count (equal bodies) | width (equal widths)")
      ->transform(CLI::CheckedTransformer(k_balances))
      ->default_str("count");
  d->add_option("--read", det.read,
                "MPI scene read: auto (all when every rank is on one node, else own) | own (each rank its "
                "rows, bodies then move to their owners) | all (every rank reads every row and keeps its "
                "own bodies and ghosts: no body moves)")
      ->transform(CLI::CheckedTransformer(k_reads))
      ->default_str("auto");
  d->add_option("--write", det.write,
                "MPI output: gather (rank 0 gathers, deduplicates and writes the sorted contacts) | ranks "
                "(each rank merges the contacts of its id_a range and writes them into the same file)")
      ->transform(CLI::CheckedTransformer(k_writes))
      ->default_str("gather");
  auto* steps =
      d->add_option("--steps", det.steps,
                    "Then measure N resident steps: each rank keeps its bodies on its GPU (or in memory), "
                    "refreshes its ghosts through MPI and detects again, contacts left in place (checked "
                    "against the file's count); prints the median step")
          ->check(CLI::NonNegativeNumber);
  d->add_option("--skin", det.skin,
                "Verlet skin (world length, default 0): the engines keep their candidate pairs across the "
                "--steps and reuse them while the bodies moved less than skin/2 (stage skin in the step "
                "times); contacts unchanged")
      ->check(CLI::NonNegativeNumber);
  d->add_option("--spin", det.spin,
                "Radians per step (default 0): in the --steps every ellipsoid turns by W·step about a fixed "
                "axis drawn from its id, and the ghosts' orientations refresh through MPI; the last step's "
                "contacts are then checked against the turned bodies detected from scratch")
      ->needs(steps);
  d->add_flag("-q,--quiet", det.quiet, "No summary");

  // compare
  std::string cmp_a, cmp_b;
  auto* c = app.add_subcommand(
      "compare", "Are the /contacts datasets of two contact files byte-identical? (0 yes, 1 no)");
  c->add_option("a", cmp_a, "Contacts file")->required();
  c->add_option("b", cmp_b, "Contacts file")->required();

  // study
  StudyOptions study;
  std::vector<std::string> study_backends;
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
  st->add_option("--backends", study_backends, "cpu, cuda (default: cpu, and cuda when a GPU is present)")
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

  // bench-broad
  BroadBenchOptions bb;
  auto* bbc = app.add_subcommand(
      "bench-broad",
      "Timing of the broad phases (grid, levels, sweep, brute, auto) x scene families x N on one backend: "
      "table and CSV; no Bullet needed");
  bbc->add_option("--families", bb.families, "Families to run (default: all)")
      ->delimiter(',')
      ->check(CLI::IsMember(broad_bench_families()));
  bbc->add_option("--lo", bb.lo, "First N = 2^lo")->capture_default_str();
  bbc->add_option("--hi", bb.hi, "Last N = 2^hi")->capture_default_str();
  bbc->add_option("--step", bb.step, "log2 N step")->check(CLI::PositiveNumber)->capture_default_str();
  bbc->add_option("--backend", bb.backend, "cpu | cuda")
      ->transform(CLI::CheckedTransformer(
          std::map<std::string, Backend>{{"cpu", Backend::cpu}, {"cuda", Backend::cuda}}))
      ->default_str("cpu");
  bbc->add_option("--precision", bb.precision, "fp32 | fp64 | mixed")
      ->transform(CLI::CheckedTransformer(k_precisions))
      ->default_str("fp64");
  bbc->add_option("--repetitions", bb.repetitions, "Time = median of this many warm detections")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  bbc->add_option("--threads", bb.threads, "CPU backend threads (0: all cores)")
      ->check(CLI::NonNegativeNumber);
  bbc->add_option("--brute-hi", bb.brute_hi, "brute runs while N <= 2^brute-hi")->capture_default_str();
  bbc->add_option("--sweep-hi", bb.sweep_hi, "sweep runs while N <= 2^sweep-hi")->capture_default_str();
  bbc->add_option("--budget", bb.budget_s,
                  "Seconds: a broad phase slower than this at some N is not run at larger N of the family")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  bbc->add_option("--seed", bb.seed, "Scene seed")->capture_default_str();
  bbc->add_option("--csv", bb.csv, "Also write the runs as CSV");

#if defined(CONTACTGRID_HAVE_BULLET)
  // validate
  std::string val_scene, val_contacts, val_bullet = "auto";
  ValidateOptions val;
  auto* v = app.add_subcommand(
      "validate", "Compare a contacts file with Bullet 3.24 (CONTRACT §4); PASS exits 0, FAIL 1");
  v->add_option("scene", val_scene, "Scene file (.h5)")->required();
  v->add_option("contacts", val_contacts, "Contacts file (.h5) written by detect")->required();
  v->add_option("--pos-eps", val.pos_eps,
                "Largest position error allowed (length units; for pairs with an ellipsoid, times the pair's "
                "larger bounding radius, and also the largest distance error)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  v->add_option("--angle-deg", val.angle_deg, "Largest angle between normals allowed (degrees)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  v->add_option(
       "--bullet-precision,--bullet", val_bullet,
       "auto | double | float: Bullet build to compare with; auto: float for scenes with ellipsoids "
       "(double Bullet's EPA is degenerate on many ellipsoid pairs), double otherwise (float Bullet is "
       "wrong far from the origin and for nearly coincident centres)")
      ->check(CLI::IsMember({"auto", "double", "float"}))
      ->capture_default_str();
  v->add_option("--shallow", val.shallow_threshold,
                "Ellipsoid pairs only we report, judged correct and shallower than this, are shallow Bullet "
                "misses (accepted; length units; default: a quarter of Bullet's ellipsoid margin 0.04)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  v->add_option("--sample", val.sample,
                "Validate K random sub-boxes instead of the whole scene (large scenes)");
  v->add_option("--seed", val.seed, "Seed of the sub-box choice")->capture_default_str();

  // bench
  BenchOptions bench;
  std::vector<std::string> bench_backends;
  bool bench_no_plot = false;
  auto* b =
      app.add_subcommand("bench", "Timing study: engine vs Bullet for N = 2^lo … 2^hi (table, CSV, plots)");
  b->add_option("--kind", bench.kind,
                "spheres (double Bullet, warm step) | ellipsoids | mixed (float Bullet with the exact "
                "ellipsoid support, from scratch; narrow-phase counters)")
      ->transform(CLI::CheckedTransformer(k_bench_kinds))
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
  b->add_option("--backend", bench_backends, "cpu | cuda (repeatable; default: cpu, and cuda when present)")
      ->check(CLI::IsMember({"cpu", "cuda"}));
  b->add_option("--threads", bench.threads, "CPU backend threads (0: all cores)");
  b->add_option("--precision", bench.precision, "fp32 | fp64 | mixed: the engine's precision mode")
      ->transform(CLI::CheckedTransformer(k_precisions))
      ->default_str("fp64");
  b->add_option("--seed", bench.seed, "Scene seed")->capture_default_str();
  b->add_option("--csv", bench.csv, "CSV output")->capture_default_str();
  b->add_option("--plot-prefix", bench.plot_prefix, "Plot file prefix (PNG and SVG); default: the CSV name");
  b->add_flag("--no-plot", bench_no_plot, "Do not run gnuplot");
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

  if (g->parsed()) {
    if (session.rank() != 0) return 0;  // one writer
    if (!offset.empty()) gen.offset = {offset[0], offset[1], offset[2]};
    if ((gen.kind == "polydisperse" || gen.kind == "bimodal" || gen.kind == "intruders") &&
        rlow_opt->count() == 0)
      gen.radius_low = gen.radius_high / gen_ratio;
    if (aspect_opt->count() > 0) {
      if (gen.kind != "ellipsoids" && gen.kind != "mixed")
        throw UsageError("--max-aspect applies to --kind ellipsoids or mixed");
      gen.radius_low = gen.radius_high / gen_max_aspect;
    }
    return run_generate(gen_out, gen, gen_quiet);
  }
  if (d->parsed()) return run_detect(det, session);
  if (c->parsed()) return session.rank() == 0 ? run_compare(cmp_a, cmp_b) : 0;
  if (st->parsed()) {
    if (session.rank() != 0) return 0;
    for (const auto& name : study_backends)
      study.backends.push_back(name == "cuda" ? Backend::cuda : Backend::cpu);
    run_study(study, std::cout, std::cerr);
    return 0;
  }
  if (bbc->parsed()) {
    if (session.rank() != 0) return 0;
    run_broad_bench(bb, std::cout);
    return 0;
  }
#if defined(CONTACTGRID_HAVE_BULLET)
  if (v->parsed()) {
    if (session.rank() != 0) return 0;
    val.bullet = parse_bullet_precision(val_bullet);
    const ValidateReport report = validate_files(val_scene, val_contacts, val);
    fmt::print("{}", report.text());
    return report.pass ? 0 : 1;
  }
  if (b->parsed()) {
    if (session.rank() != 0) return 0;
    for (const auto& name : bench_backends)
      bench.backends.push_back(name == "cuda" ? Backend::cuda : Backend::cpu);
    bench.plot = !bench_no_plot;
    run_bench(bench);
    return 0;
  }
#endif
  return 2;
}

}  // namespace cg
