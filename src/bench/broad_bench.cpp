// `contactgrid bench-broad` (broad_bench.hpp).
#include "bench/broad_bench.hpp"

#include <fmt/format.h>
#include <fmt/ostream.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <fstream>
#include <map>
#include <optional>
#include <ostream>

#include "errors.hpp"
#include "run/progress.hpp"
#include "scene/generate.hpp"

namespace cg {
namespace {

struct Family {
  std::string name, kind;
  double r_low, r_high, large_fraction = 0.1;
  std::uint64_t intruders = 0;
};

const std::vector<Family>& families() {
  static const std::vector<Family> f{{"uniform", "uniform", 0.5, 1.0},
                                     {"bimodal10", "bimodal", 0.1, 1.0},
                                     {"bimodal100", "bimodal", 0.01, 1.0},
                                     {"loguniform1000", "polydisperse", 0.001, 1.0},
                                     {"intruder1", "intruders", 0.01, 1.0, 0, 1},
                                     {"intruders64", "intruders", 1.0, 100.0, 0, 64}};
  return f;
}

constexpr BroadPhase kPhases[] = {BroadPhase::grid, BroadPhase::levels, BroadPhase::sweep, BroadPhase::brute,
                                  BroadPhase::automatic};

struct Timing {
  double seconds = 0;
  std::uint64_t contacts = 0, pair_tests = 0;
  BroadPhase ran = BroadPhase::grid;
  int levels = 0;
  std::string stages;  // BroadBenchOptions::stage_times: the last repetition's stages and counts
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

// Seconds now: wall clock, or the process's CPU time (every thread's; BroadBenchOptions::cpu_time).
double now(bool cpu_time) {
  if (cpu_time) {
    timespec t{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
  }
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

template <class Real>
Timing time_engine(const BroadBenchOptions& o, const BodiesView& bodies, BroadPhase bp) {
  EngineOptions e;
  e.backend = o.backend;
  e.threads = o.threads;
  e.broad_phase = bp;
  e.fp32_broad_phase = o.precision == Precision::mixed;
  if (o.estimate) e.on_pair_estimate = [](const PairEstimate&) {};
  Engine<Real> engine(e);
  engine.set_resident(bodies);
  Timing t;
  t.contacts = engine.detect_resident();  // warm-up (the workspace grows once)
  std::vector<double> s;
  for (int k = 0; k < o.repetitions; ++k) {
    const double t0 = now(o.cpu_time);
    const std::size_t c = engine.detect_resident();
    s.push_back(now(o.cpu_time) - t0);
    if (c != t.contacts) throw std::runtime_error("bench-broad: a repeated detection found other contacts");
  }
  t.seconds = median(s);
  t.pair_tests = engine.stats().pair_tests;
  t.ran = engine.stats().broad_phase;
  t.levels = engine.stats().levels;
  if (o.stage_times) {
    const EngineStats& st = engine.stats();
    for (const StageTime& stage : engine.times())
      t.stages += fmt::format("{} {:.3f}  ", stage.name, 1e3 * stage.seconds);
    t.stages += fmt::format("(ms; levels {}, entries {}, pair tests {}, candidates {})", st.levels,
                            st.entries, st.pair_tests, st.candidates);
  }
  return t;
}

// Seconds a call of `bp` is predicted to take at N = 2^lg from its times at smaller N of the family
// (log2 N → seconds): the last grown as N^e, e from the last two (clamped to [1, 2]) or, from one, 1
// (grid, levels) or 2 (sweep, brute: their tests grow faster than N). Negative: no time yet.
double predicted_seconds(const std::map<int, double>& history, int lg, BroadPhase bp) {
  if (history.empty()) return -1;
  const auto last = std::prev(history.end());
  double e = bp == BroadPhase::sweep || bp == BroadPhase::brute ? 2.0 : 1.0;
  if (history.size() >= 2) {
    const auto before = std::prev(last);
    if (before->second > 0 && last->second > 0 && last->first > before->first)
      e = std::clamp(std::log2(last->second / before->second) / double(last->first - before->first), 1.0,
                     2.0);
  }
  return last->second * std::exp2(e * double(lg - last->first));
}

Timing time_phase(const BroadBenchOptions& o, const BodiesView& bodies, BroadPhase bp) {
  return o.precision == Precision::fp32 ? time_engine<float>(o, bodies, bp)
                                        : time_engine<double>(o, bodies, bp);
}

}  // namespace

const std::vector<std::string>& broad_bench_families() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const Family& f : families()) n.push_back(f.name);
    return n;
  }();
  return names;
}

void run_broad_bench(const BroadBenchOptions& o, std::ostream& out) {
  if (o.lo < 1 || o.hi > 28 || o.lo > o.hi || o.step < 1)
    throw UsageError("bench-broad: need 1 <= lo <= hi <= 28 and step >= 1");
  if (o.repetitions < 1) throw UsageError("bench-broad: repetitions must be >= 1");
  if (o.cpu_time && o.backend != Backend::cpu)
    throw UsageError("bench-broad: --cpu-time times the CPU backend only (a GPU's work is not CPU time)");
  std::vector<Family> run;
  for (const Family& f : families())
    if (o.families.empty() || std::find(o.families.begin(), o.families.end(), f.name) != o.families.end())
      run.push_back(f);
  std::ofstream csv;
  if (!o.csv.empty()) {
    csv.open(o.csv);
    if (!csv) throw IoError("bench-broad: cannot write " + o.csv);
    csv << "family,n,log2n,broad_phase,ran,levels,seconds,contacts,pair_tests,ns_per_contact\n";
  }
  fmt::print(out,
             "bench-broad: backend {}, precision {}, median of {} ({} seconds; '-': not run; '>t': skipped, "
             "predicted t seconds a call)\n",
             to_string(o.backend), to_string(o.precision), o.repetitions, o.cpu_time ? "CPU" : "wall");
  fmt::print(out, "{:<15} {:>9} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}  {:<7} {:>9} {:>8} {:>9} {:>9}\n",
             "family", "N", "contacts", "grid", "levels", "sweep", "brute", "auto", "best", "auto/best",
             "ns/cont", "/uniform", "/unif/c");
  std::map<int, double> uniform_best, uniform_per_contact;  // log2 N → the uniform row's best (per contact)
  const std::uint64_t total = std::uint64_t(run.size()) * std::uint64_t((o.hi - o.lo) / o.step + 1);
  Progress progress("bench-broad", "rows", total);
  std::uint64_t done = 0, rows_with_auto = 0, auto_near_best = 0;
  std::vector<std::string> auto_far;  // rows where auto is more than 10 % above the best
  for (const Family& f : run) {
    std::map<BroadPhase, bool> over_budget;
    std::map<BroadPhase, std::map<int, double>> history;  // per broad phase: log2 N → seconds a call
    for (int lg = o.lo; lg <= o.hi; lg += o.step) {
      GenerateOptions g;
      g.kind = f.kind;
      g.count = std::uint64_t(1) << lg;
      g.seed = o.seed;
      g.contacts_per_body = o.contacts_per_body;
      g.radius_low = f.r_low;
      g.radius_high = f.r_high;
      g.large_fraction = f.large_fraction;
      g.intruders = std::max<std::uint64_t>(1, std::min<std::uint64_t>(f.intruders, g.count));
      const Scene scene = generate_scene(g);
      const BodiesView bodies{{scene.sphere_position.data(), scene.sphere_position.size()},
                              {scene.sphere_radius.data(), scene.sphere_radius.size()},
                              {},
                              {}};
      // auto's pick: the engine's rule on the bounds it computes (the device's equal the host's)
      const BroadPhase pick =
          resolved_broad_phase(BroadPhase::automatic, compute_bounds(bodies), o.precision, o.backend);
      // the broad phases of o.phases, and auto's pick where auto is among them (auto/best compares it)
      const auto listed = [&](BroadPhase bp) {
        return o.phases.empty() || std::find(o.phases.begin(), o.phases.end(), bp) != o.phases.end();
      };
      const auto timed = [&](BroadPhase bp) {
        return listed(bp) || (bp == pick && listed(BroadPhase::automatic));
      };
      std::map<BroadPhase, Timing> t;
      std::map<BroadPhase, double> skipped;  // predicted seconds a call of a skipped run
      std::optional<std::uint64_t> contacts;
      for (BroadPhase bp : kPhases) {
        const bool is_auto = bp == BroadPhase::automatic;
        const BroadPhase as = is_auto ? pick : bp;
        if (!timed(bp)) {
          continue;
        } else if (is_auto && t.count(pick)) {  // the same code, timed in this row
          t[bp] = t[pick];
        } else if (is_auto && skipped.count(pick)) {
          skipped[bp] = skipped[pick];
          continue;
        } else {
          if (!is_auto && (over_budget[bp] || (bp == BroadPhase::brute && lg > o.brute_hi) ||
                           (bp == BroadPhase::sweep && lg > o.sweep_hi)))
            continue;
          const double p = predicted_seconds(history[as], lg, as);
          if (o.limit_s > 0 && p >= 0 && p * (1 + o.repetitions) > o.limit_s) {
            skipped[bp] = p;
            continue;
          }
          t[bp] = time_phase(o, bodies, bp);
          history[as][lg] = t[bp].seconds;
        }
        if (contacts && *contacts != t[bp].contacts)
          throw std::runtime_error(fmt::format("bench-broad: {} N = 2^{}: {} finds {} contacts, another {}",
                                               f.name, lg, to_string(bp), t[bp].contacts, *contacts));
        contacts = t[bp].contacts;
        if (t[bp].seconds > o.budget_s) over_budget[bp] = true;
        if (csv)
          csv << fmt::format("{},{},{},{},{},{},{:.6g},{},{},{:.4g}\n", f.name, g.count, lg, to_string(bp),
                             to_string(t[bp].ran), t[bp].levels, t[bp].seconds, t[bp].contacts,
                             t[bp].pair_tests,
                             1e9 * t[bp].seconds / double(std::max<std::uint64_t>(1, t[bp].contacts)));
      }
      std::optional<BroadPhase> best;
      double best_s = 0;
      for (const auto& [bp, tm] : t)
        if (bp != BroadPhase::automatic && (!best || tm.seconds < best_s)) best = bp, best_s = tm.seconds;
      const double per_contact = best_s / double(std::max<std::uint64_t>(1, contacts.value_or(0)));
      if (f.name == "uniform" && best) {
        uniform_best[lg] = best_s;
        uniform_per_contact[lg] = per_contact;
      }
      auto cell = [&](BroadPhase bp) {
        if (t.count(bp)) return fmt::format("{:.4f}", t[bp].seconds);
        if (skipped.count(bp)) return fmt::format(">{:.2g}", skipped[bp]);
        return std::string("-");
      };
      const bool timed_auto = t.count(BroadPhase::automatic) && best;
      const double auto_ratio = timed_auto ? t[BroadPhase::automatic].seconds / best_s : 0.0;
      if (timed_auto) {
        ++rows_with_auto;
        if (auto_ratio <= 1.10)
          ++auto_near_best;
        else
          auto_far.push_back(fmt::format("{} 2^{} ({}: {:.2f}x)", f.name, lg, to_string(pick), auto_ratio));
      }
      const std::string vs_uniform = best && uniform_best.count(lg)
                                         ? fmt::format("{:.2f}", best_s / uniform_best[lg])
                                         : std::string("-");
      const std::string vs_uniform_per_contact =
          best && uniform_per_contact.count(lg) ? fmt::format("{:.2f}", per_contact / uniform_per_contact[lg])
                                                : std::string("-");
      fmt::print(
          out, "{:<15} {:>9} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}  {:<7} {:>9} {:>8} {:>9} {:>9}\n",
          f.name, g.count, contacts.value_or(0), cell(BroadPhase::grid), cell(BroadPhase::levels),
          cell(BroadPhase::sweep), cell(BroadPhase::brute),
          fmt::format("{}:{}", to_string(pick)[0], cell(BroadPhase::automatic)),
          best ? to_string(*best) : "-", timed_auto ? fmt::format("{:.2f}", auto_ratio) : std::string("-"),
          best ? fmt::format("{:.1f}", 1e9 * per_contact) : std::string("-"), vs_uniform,
          vs_uniform_per_contact);
      if (o.stage_times)
        for (const auto& [bp, tm] : t)
          if (bp != BroadPhase::automatic) fmt::print(out, "    {:<7} {}\n", to_string(bp), tm.stages);
      out.flush();
      progress.update(++done);
    }
  }
  fmt::print(out, "auto within 10 % of the best: {} of {} rows{}{}\n", auto_near_best, rows_with_auto,
             auto_far.empty() ? "" : "; not: ", fmt::join(auto_far, ", "));
}

}  // namespace cg
