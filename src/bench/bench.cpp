// The timing study behind `contactgrid bench` (see bench.hpp for what is timed and the CSV columns).
//
// Invariants: every row's scene is generated from (seed + log2 N) alone, so a row can be re-run by
// itself; the CSV is written to "<csv>.tmp.<pid>" and renamed (as every output of contactgrid);
// the plot is a separate step that can be re-run by hand from the CSV.
#include "bench/bench.hpp"

#include <fmt/format.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numeric>
#include <ostream>

#include "errors.hpp"
#include "io/scene_file.hpp"
#include "io/text_file.hpp"
#include "run/progress.hpp"
#include "scene/generate.hpp"
#include "stage.hpp"
#include "timing.hpp"
#include "validate/bullet_oracle.hpp"

extern char** environ;

namespace cg {
namespace {

namespace fs = std::filesystem;
std::string field(double v, const char* f = "{:.6g}") {
  return v >= 0 && std::isfinite(v) ? fmt::format(fmt::runtime(f), v) : std::string();
}

std::string find_on_path(const std::string& name) {
  const char* path = std::getenv("PATH");
  if (!path) return {};
  std::string p = path;
  for (std::size_t start = 0; start <= p.size();) {
    const std::size_t end = std::min(p.find(':', start), p.size());
    const fs::path cand =
        fs::path(p.substr(start, end - start).empty() ? "." : p.substr(start, end - start)) / name;
    if (::access(cand.c_str(), X_OK) == 0) return cand.string();
    start = end + 1;
  }
  return {};
}

// Runs argv (no shell) and returns its exit status (-1 if it could not start or was killed).
int run_program(const std::vector<std::string>& args) {
  std::vector<std::string> a = args;
  std::vector<char*> argv;
  for (auto& s : a) argv.push_back(s.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  if (::posix_spawn(&pid, a[0].c_str(), nullptr, nullptr, argv.data(), environ) != 0) return -1;
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

void check_options(const BenchOptions& o) {
  if (o.lo < 1 || o.lo > 28) throw UsageError("--lo must be in 1 … 28");
  if (o.engine_hi < o.lo - 1 || o.engine_hi > 28) throw UsageError("--engine-hi must be in lo-1 … 28");
  if (o.bullet_hi > 24) throw UsageError("--bullet-hi must be <= 24 (Bullet needs ~20 s at 2^20)");
  if (std::max(o.engine_hi, o.bullet_hi) < o.lo) throw UsageError("nothing to run: hi < lo");
  if (o.repetitions < 1) throw UsageError("--repetitions must be >= 1");
  if (!(o.radius_low > 0) || !(o.radius_high >= o.radius_low))
    throw UsageError("radii must satisfy 0 < radius_low <= radius_high");
  if (!(o.contacts_per_body > 0)) throw UsageError("--contacts-per-body must be > 0");
  if (o.csv.empty()) throw UsageError("--csv must name a file");
  if (!(o.max_aspect >= 1) || !std::isfinite(o.max_aspect)) throw UsageError("--max-aspect must be >= 1");
  if (!(o.ellipsoid_fraction >= 0 && o.ellipsoid_fraction <= 1))
    throw UsageError("--ellipsoid-fraction must be in [0, 1]");
  for (Backend b : o.backends) {
    if (b == Backend::automatic) throw UsageError("bench: --backend must be cpu or cuda");
    if (b == Backend::cuda && !cuda_available())
      throw UsageError("bench: --backend cuda asked for, but no CUDA device is usable in this build");
  }
}

// The generator options of the row N = 2^e (seeded by seed + e alone).
GenerateOptions scene_options(const BenchOptions& o, int e) {
  GenerateOptions g;
  g.kind = o.kind == BenchKind::spheres ? "uniform" : to_string(o.kind);
  g.count = std::uint64_t(1) << e;
  g.seed = o.seed + std::uint64_t(e);
  g.radius_high = o.radius_high;
  g.radius_low = o.kind == BenchKind::spheres ? o.radius_low : o.radius_high / o.max_aspect;
  g.contacts_per_body = o.contacts_per_body;
  g.ellipsoid_fraction = o.ellipsoid_fraction;
  return g;
}

// Times the engine on backend b (one untimed warm-up, then the median of o.repetitions calls) and
// records its contact count and, for scenes with shapes, its narrow-phase counters.
void time_engine(const BenchOptions& o, Backend b, const BodiesView& view, BenchRow& row) {
  EngineOptions eo;
  eo.backend = b;
  eo.threads = o.threads;
  eo.fp32_broad_phase = o.precision == Precision::mixed;
  std::int64_t count = 0;
  std::vector<double> times, narrow_times;
  NarrowCounters nc;
  auto run = [&](auto real) {
    Engine<decltype(real)> engine(eo);
    count = std::int64_t(engine.detect(view).size());  // warm-up, untimed
    for (int r = 0; r < o.repetitions; ++r) {
      const auto t0 = WallClock::now();
      const auto c = engine.detect(view);
      times.push_back(seconds_since(t0));
      if (std::int64_t(c.size()) != count)
        throw Error(fmt::format("bench: engine ({}) gave {} then {} contacts at N = {}", to_string(b), count,
                                c.size(), row.n));
      for (const StageTime& t : engine.times())
        if (t.name == detail::name(detail::EngineStage::narrow)) narrow_times.push_back(t.seconds);
    }
    const EngineStats& st = engine.stats();
    nc = {st.candidates, st.narrow_hard, st.narrow_fallbacks, st.narrow_unconverged, -1};
  };
  if (o.precision == Precision::fp32)
    run(float{});
  else
    run(double{});
  row.engine_s[b] = median(times);
  row.engine_contacts[b] = count;
  if (row.contacts < 0) row.contacts = count;
  if (!view.shape.empty()) {
    if (!narrow_times.empty()) nc.narrow_s = median(narrow_times);
    row.narrow[b] = nc;
  }
}

// Spheres: every count measured is the same. Shapes: the engine backends' counts are the same and
// Bullet's is within bullet_count_allowance() of them (float Bullet's shallow misses).
void judge_agreement(BenchRow& row, BenchKind kind) {
  std::vector<std::int64_t> counts;
  for (const auto& [b, c] : row.engine_contacts) counts.push_back(c);
  const bool engine_same =
      std::all_of(counts.begin(), counts.end(), [&](std::int64_t c) { return c == counts.front(); });
  row.compared = counts.size() + (row.bullet_contacts >= 0 ? 1 : 0) >= 2;
  if (!row.compared) return;
  if (row.bullet_contacts < 0 || counts.empty()) {
    row.agree = engine_same;
    return;
  }
  const std::int64_t diff = std::abs(row.bullet_contacts - counts.front());
  row.agree = engine_same &&
              (kind == BenchKind::spheres ? diff == 0 : diff <= bullet_count_allowance(counts.front()));
}

double engine_time(const BenchRow& row, Backend b) {
  auto it = row.engine_s.find(b);
  return it == row.engine_s.end() ? -1.0 : it->second;
}

// The narrow counters of the first backend run (the same on every backend), or none.
const NarrowCounters* first_narrow(const BenchRow& row, const std::vector<Backend>& backends) {
  for (Backend b : backends)
    if (auto it = row.narrow.find(b); it != row.narrow.end()) return &it->second;
  return nullptr;
}

double pairs_per_s(const BenchRow& row, Backend b) {
  auto it = row.narrow.find(b);
  return it == row.narrow.end() || !(it->second.narrow_s > 0)
             ? -1.0
             : double(it->second.candidates) / it->second.narrow_s;
}

double speedup(const BenchRow& row, Backend b, double bullet) {
  const double e = engine_time(row, b);
  return e > 0 && bullet >= 0 ? bullet / e : -1.0;
}

std::string num(double v, const char* f) {
  return v >= 0 ? fmt::format(fmt::runtime(f), v) : std::string("-");
}

std::vector<std::string> csv_lines(const BenchResult& r) {
  std::vector<std::string> lines;
  lines.push_back(
      "n,log2n,contacts,bullet_contacts,agree,bullet_scratch_s,bullet_warm_s,engine_cpu_s,engine_cuda_s,"
      "speedup_cpu_vs_scratch,speedup_cpu_vs_warm,speedup_cuda_vs_scratch,speedup_cuda_vs_warm");
  for (const BenchRow& row : r.rows) {
    lines.push_back(fmt::format(
        "{},{},{},{},{},{},{},{},{},{},{},{},{}", row.n, int(std::lround(std::log2(double(row.n)))),
        row.contacts >= 0 ? std::to_string(row.contacts) : "",
        row.bullet_contacts >= 0 ? std::to_string(row.bullet_contacts) : "",
        row.compared ? (row.agree ? "yes" : "no") : "", field(row.bullet_scratch_s), field(row.bullet_warm_s),
        field(engine_time(row, Backend::cpu)), field(engine_time(row, Backend::cuda)),
        field(speedup(row, Backend::cpu, row.bullet_scratch_s), "{:.4g}"),
        field(speedup(row, Backend::cpu, row.bullet_warm_s), "{:.4g}"),
        field(speedup(row, Backend::cuda, row.bullet_scratch_s), "{:.4g}"),
        field(speedup(row, Backend::cuda, row.bullet_warm_s), "{:.4g}")));
  }
  return lines;
}

std::vector<std::string> shape_csv_lines(const BenchResult& r, BenchKind kind,
                                         const std::vector<Backend>& backends) {
  std::vector<std::string> lines{kShapeCsvColumns};
  for (const BenchRow& row : r.rows) {
    const NarrowCounters* nc = first_narrow(row, backends);
    auto counter = [&](std::uint64_t NarrowCounters::*m) {
      return nc ? std::to_string(nc->*m) : std::string();
    };
    auto narrow_s = [&](Backend b) {
      auto it = row.narrow.find(b);
      return it == row.narrow.end() ? -1.0 : it->second.narrow_s;
    };
    lines.push_back(fmt::format(
        "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}", row.n,
        int(std::lround(std::log2(double(row.n)))), to_string(kind), row.ellipsoids,
        row.contacts >= 0 ? std::to_string(row.contacts) : "",
        row.bullet_contacts >= 0 ? std::to_string(row.bullet_contacts) : "",
        row.compared ? (row.agree ? "yes" : "no") : "", field(row.bullet_scratch_s),
        field(engine_time(row, Backend::cpu)), field(engine_time(row, Backend::cuda)),
        field(speedup(row, Backend::cpu, row.bullet_scratch_s), "{:.4g}"),
        field(speedup(row, Backend::cuda, row.bullet_scratch_s), "{:.4g}"),
        counter(&NarrowCounters::candidates), counter(&NarrowCounters::narrow_hard),
        counter(&NarrowCounters::narrow_fallbacks), counter(&NarrowCounters::narrow_unconverged),
        field(narrow_s(Backend::cpu)), field(narrow_s(Backend::cuda)),
        field(pairs_per_s(row, Backend::cpu), "{:.4g}"), field(pairs_per_s(row, Backend::cuda), "{:.4g}")));
  }
  return lines;
}

void print_shape_table(const BenchResult& r, const std::vector<Backend>& backends, std::ostream& out) {
  std::string head = fmt::format("{:>9} {:>9} {:>9} {:>12}", "N", "contacts", "Bullet", "Bullet fl s");
  for (Backend b : backends)
    head += fmt::format(" {:>10} {:>9}", fmt::format("{} s", to_string(b)), "x Bullet");
  head += fmt::format(" {:>6} {:>9} {:>6} {:>5} {:>5}", "agree", "candid.", "hard", "fallb", "unconv");
  for (Backend b : backends) head += fmt::format(" {:>13}", fmt::format("{} pairs/s", to_string(b)));
  out << head << '\n';
  for (const BenchRow& row : r.rows) {
    std::string line =
        fmt::format("{:>9} {:>9} {:>9} {:>12}", row.n, row.contacts >= 0 ? std::to_string(row.contacts) : "-",
                    row.bullet_contacts >= 0 ? std::to_string(row.bullet_contacts) : "-",
                    num(row.bullet_scratch_s, "{:.4g}"));
    for (Backend b : backends)
      line += fmt::format(" {:>10} {:>9}", num(engine_time(row, b), "{:.4g}"),
                          num(speedup(row, b, row.bullet_scratch_s), "{:.1f}"));
    line += fmt::format(" {:>6}", row.compared ? (row.agree ? "yes" : "NO") : "-");
    if (const NarrowCounters* nc = first_narrow(row, backends))
      line += fmt::format(" {:>9} {:>6} {:>5} {:>5}", nc->candidates, nc->narrow_hard, nc->narrow_fallbacks,
                          nc->narrow_unconverged);
    else
      line += fmt::format(" {:>9} {:>6} {:>5} {:>5}", "-", "-", "-", "-");
    for (Backend b : backends) line += fmt::format(" {:>13}", num(pairs_per_s(row, b), "{:.4g}"));
    out << line << '\n';
  }
}

void write_csv(const std::string& path, const std::vector<std::string>& lines) {
  std::string text;
  for (const auto& l : lines) text += l + '\n';
  write_text_file(path, text);
}

void print_table(const BenchResult& r, const std::vector<Backend>& backends, std::ostream& out) {
  std::string head =
      fmt::format("{:>10} {:>10} {:>12} {:>12}", "N", "contacts", "Bullet scr s", "Bullet warm s");
  for (Backend b : backends)
    head += fmt::format(" {:>12} {:>9} {:>9}", fmt::format("{} s", to_string(b)), "x scratch", "x warm");
  head += fmt::format(" {:>6}", "agree");
  out << head << '\n';
  for (const BenchRow& row : r.rows) {
    std::string line = fmt::format("{:>10} {:>10} {:>12} {:>12}", row.n,
                                   row.contacts >= 0 ? row.contacts : row.bullet_contacts,
                                   num(row.bullet_scratch_s, "{:.4g}"), num(row.bullet_warm_s, "{:.4g}"));
    for (Backend b : backends) {
      line += fmt::format(" {:>12} {:>9} {:>9}", num(engine_time(row, b), "{:.4g}"),
                          num(speedup(row, b, row.bullet_scratch_s), "{:.1f}"),
                          num(speedup(row, b, row.bullet_warm_s), "{:.1f}"));
    }
    line += fmt::format(" {:>6}", row.compared ? (row.agree ? "yes" : "NO") : "-");
    out << line << '\n';
  }
}

}  // namespace

const char* to_string(BenchKind kind) {
  static constexpr const char* names[] = {"spheres", "ellipsoids", "mixed"};  // BenchKind's order
  return names[static_cast<int>(kind)];
}

std::int64_t bullet_count_allowance(std::int64_t engine_contacts) {
  const double expected = kBulletShallowMissRate * double(std::max<std::int64_t>(engine_contacts, 0));
  return std::max<std::int64_t>(3, std::int64_t(std::ceil(expected + 3 * std::sqrt(expected))));
}

double loglog_slope(const std::vector<double>& x, const std::vector<double>& y, double x_min) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int n = 0;
  for (std::size_t i = 0; i < x.size() && i < y.size(); ++i) {
    if (!(x[i] >= x_min) || !(y[i] > 0) || !(x[i] > 0)) continue;
    const double lx = std::log(x[i]), ly = std::log(y[i]);
    sx += lx, sy += ly, sxx += lx * lx, sxy += lx * ly, ++n;
  }
  const double den = n * sxx - sx * sx;
  if (n < 2 || den == 0) return std::numeric_limits<double>::quiet_NaN();
  return (n * sxy - sx * sy) / den;
}

std::string bench_plot_script(const BenchOptions& o) {
  std::vector<fs::path> cands;
  if (!o.plot_script.empty()) return fs::exists(o.plot_script) ? o.plot_script : std::string();
  if (const char* env = std::getenv("CONTACTGRID_PLOT_SCRIPT"); env && *env) cands.emplace_back(env);
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) cands.push_back(self.parent_path().parent_path() / "share" / "contactgrid" / "plot_bench.gp");
#ifdef CG_PLOT_SCRIPT
  cands.emplace_back(CG_PLOT_SCRIPT);
#endif
  for (const auto& c : cands)
    if (fs::exists(c, ec)) return c.string();
  return {};
}

BenchResult run_bench(const BenchOptions& o, std::ostream& out) {
  check_options(o);
  std::vector<Backend> backends = o.backends;
  if (backends.empty()) {
    backends.push_back(Backend::cpu);
    if (cuda_available()) backends.push_back(Backend::cuda);
  }
  BenchResult result;
  const int hi = std::max(o.bullet_hi, o.engine_hi);
  out << fmt::format(
      "bench: {}N = 2^{} … 2^{} (Bullet {} to 2^{}, engine {} to 2^{}), {} repetitions, "
      "seed {}\n",
      o.kind == BenchKind::spheres ? ""
                                   : fmt::format("{}, aspect <= 1:{:g}, ", to_string(o.kind), o.max_aspect),
      o.lo, hi, o.kind == BenchKind::spheres ? "double" : "float, exact ellipsoid support", o.bullet_hi,
      to_string(o.precision), o.engine_hi, o.repetitions, o.seed);
  Progress bar("bench", "sizes", std::uint64_t(std::max(0, hi - o.lo + 1)));
  for (int e = o.lo; e <= hi; ++e) {
    BenchRow row;
    row.n = std::uint64_t(1) << e;
    Scene scene = generate_scene(scene_options(o, e));
    row.ellipsoids = scene.ellipsoid_count();
    OracleBodies bullet_bodies;
    if (e <= o.bullet_hi) {
      std::vector<std::int64_t> ids(scene.size());
      std::iota(ids.begin(), ids.end(), std::int64_t(0));
      double extent = 0;
      bullet_bodies = oracle_bodies(scene, ids, bullet_scale_of(scene), extent);
    }
    if (e <= o.engine_hi) {
      const BodyRows rows = body_rows(std::move(scene), o.kind != BenchKind::spheres);
      const BodiesView view{rows.position, rows.radius, {}, {}, rows.shape, rows.semi_axes, rows.orientation};
      for (Backend b : backends) time_engine(o, b, view, row);
    }
    if (e <= o.bullet_hi) {
      // Spheres: double Bullet with a warm step (the course's study); ellipsoids: float Bullet with
      // the exact support (double Bullet's EPA is degenerate on 17–20 % of ellipsoid pairs).
      const bool spheres = o.kind == BenchKind::spheres;
      const OracleResult br = bullet_collide(bullet_bodies, spheres ? Precision::fp64 : Precision::fp32,
                                             /*warm_step=*/spheres);
      row.bullet_contacts = std::int64_t(br.contacts.size());
      row.bullet_scratch_s = br.scratch_seconds;
      row.bullet_warm_s = br.warm_seconds;
    }
    judge_agreement(row, o.kind);
    result.rows.push_back(row);
    bar.finish();
    out << fmt::format("  N = 2^{}: done", e);
    if (row.bullet_scratch_s >= 0) out << fmt::format(" (Bullet {:.3g} s)", row.bullet_scratch_s);
    out << '\n' << std::flush;
    bar.add(1);
  }
  bar.finish();

  // Slopes over N >= 2^14.
  auto series = [&](auto get) {
    std::vector<double> x, y;
    for (const BenchRow& r : result.rows)
      if (double v = get(r); v > 0) x.push_back(double(r.n)), y.push_back(v);
    return loglog_slope(x, y, double(1 << 14));
  };
  result.slopes["bullet_scratch"] = series([](const BenchRow& r) { return r.bullet_scratch_s; });
  result.slopes["bullet_warm"] = series([](const BenchRow& r) { return r.bullet_warm_s; });
  for (Backend b : backends)
    result.slopes[std::string("engine_") + to_string(b)] = series([b](const BenchRow& r) {
      auto it = r.engine_s.find(b);
      return it == r.engine_s.end() ? -1.0 : it->second;
    });

  out << '\n';
  if (o.kind == BenchKind::spheres)
    print_table(result, backends, out);
  else
    print_shape_table(result, backends, out);
  out << "log-log slopes (N >= 2^14):";
  for (const auto& [name, s] : result.slopes)
    out << fmt::format("  {} {}", name, std::isnan(s) ? std::string("-") : fmt::format("{:.3f}", s));
  out << '\n';

  result.csv_path = o.csv;
  write_csv(o.csv,
            o.kind == BenchKind::spheres ? csv_lines(result) : shape_csv_lines(result, o.kind, backends));
  out << "wrote " << o.csv << '\n';

  if (o.plot && o.kind != BenchKind::spheres) {
    out << "plot: jobs/plot_bench.gp draws sphere tables only; the " << to_string(o.kind)
        << " table is the CSV above\n";
  } else if (o.plot) {
    std::string prefix = o.plot_prefix;
    if (prefix.empty()) {
      prefix = o.csv;
      if (prefix.size() > 4 && prefix.compare(prefix.size() - 4, 4, ".csv") == 0)
        prefix.resize(prefix.size() - 4);
    }
    const std::string script = bench_plot_script(o);
    const std::string gnuplot = find_on_path("gnuplot");
    const std::string vars = fmt::format("csv='{}'; out='{}'", o.csv, prefix);
    if (script.empty()) {
      out << "plot: jobs/plot_bench.gp not found (set CONTACTGRID_PLOT_SCRIPT); run by hand:\n"
          << "  gnuplot -e \"" << vars << "\" jobs/plot_bench.gp\n";
    } else if (gnuplot.empty()) {
      out << "plot: gnuplot is not on PATH; to plot later:\n  gnuplot -e \"" << vars << "\" " << script
          << '\n';
    } else if (int rc = run_program({gnuplot, "-e", vars, script}); rc != 0) {
      out << "plot: gnuplot failed (status " << rc << "); command: gnuplot -e \"" << vars << "\" " << script
          << '\n';
    } else {
      result.plotted = true;
      out << fmt::format("plot: {0}_time.png/.svg, {0}_loglog.png/.svg\n", prefix);
    }
  }
  return result;
}

}  // namespace cg
