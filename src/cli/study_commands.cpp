// The measuring commands of the command line: study, bench-broad, validate, bench (subcommands.hpp).
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
#if defined(CONTACTGRID_HAVE_BULLET)
#include "bench/bench.hpp"
#include "validate/validate.hpp"
#endif
#include "bench/broad_bench.hpp"
#include "study/study.hpp"
#include "study/study_families.hpp"

namespace cg::cli {

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
  bbc->add_option(
         "--contacts-per-body", args->contacts_per_body,
         "The families' density: contacts per body, as generate's (the granular rest density is about 6)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
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

}  // namespace cg::cli
