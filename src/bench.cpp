// The timing study behind `contactgrid bench` (see bench.hpp for what is timed and the CSV columns).
//
// Invariants: every row's scene is generated from (seed + log2 N) alone, so a row can be re-run by
// itself; the CSV is written to "<csv>.tmp.<pid>" and renamed (as every output of contactgrid);
// the plot is a separate step that can be re-run by hand from the CSV.
#include "bench.hpp"

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
#include <ostream>

#include "bullet_oracle.hpp"
#include "errors.hpp"
#include "generate.hpp"

extern char** environ;

namespace cg {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

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
  for (Backend b : o.backends) {
    if (b == Backend::automatic) throw UsageError("bench: --backend must be cpu or cuda");
    if (b == Backend::cuda && !cuda_available())
      throw UsageError("bench: --backend cuda asked for, but no CUDA device is usable in this build");
  }
}

std::vector<std::string> csv_lines(const BenchResult& r) {
  std::vector<std::string> lines;
  lines.push_back(
      "n,log2n,contacts,bullet_contacts,agree,bullet_scratch_s,bullet_warm_s,engine_cpu_s,engine_cuda_s,"
      "speedup_cpu_vs_scratch,speedup_cpu_vs_warm,speedup_cuda_vs_scratch,speedup_cuda_vs_warm");
  for (const BenchRow& row : r.rows) {
    auto eng = [&](Backend b) {
      auto it = row.engine_s.find(b);
      return it == row.engine_s.end() ? -1.0 : it->second;
    };
    auto speedup = [&](Backend b, double bullet) {
      const double e = eng(b);
      return e > 0 && bullet >= 0 ? bullet / e : -1.0;
    };
    lines.push_back(fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{}", row.n,
                                int(std::lround(std::log2(double(row.n)))),
                                row.contacts >= 0 ? std::to_string(row.contacts) : "",
                                row.bullet_contacts >= 0 ? std::to_string(row.bullet_contacts) : "",
                                row.compared ? (row.agree ? "yes" : "no") : "", field(row.bullet_scratch_s),
                                field(row.bullet_warm_s), field(eng(Backend::cpu)), field(eng(Backend::cuda)),
                                field(speedup(Backend::cpu, row.bullet_scratch_s), "{:.4g}"),
                                field(speedup(Backend::cpu, row.bullet_warm_s), "{:.4g}"),
                                field(speedup(Backend::cuda, row.bullet_scratch_s), "{:.4g}"),
                                field(speedup(Backend::cuda, row.bullet_warm_s), "{:.4g}")));
  }
  return lines;
}

void write_csv(const std::string& path, const std::vector<std::string>& lines) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  {
    std::ofstream f(tmp);
    for (const auto& l : lines) f << l << '\n';
    f.close();
    if (!f) {
      std::error_code ec;
      fs::remove(tmp, ec);
      throw IoError("bench: cannot write " + path);
    }
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw IoError("bench: cannot write " + path + ": " + ec.message());
  }
}

void print_table(const BenchResult& r, const std::vector<Backend>& backends, std::ostream& out) {
  std::string head =
      fmt::format("{:>10} {:>10} {:>12} {:>12}", "N", "contacts", "Bullet scr s", "Bullet warm s");
  for (Backend b : backends)
    head += fmt::format(" {:>12} {:>9} {:>9}", fmt::format("{} s", to_string(b)), "x scratch", "x warm");
  head += fmt::format(" {:>6}", "agree");
  out << head << '\n';
  auto num = [](double v, const char* f) {
    return v >= 0 ? fmt::format(fmt::runtime(f), v) : std::string("-");
  };
  for (const BenchRow& row : r.rows) {
    std::string line = fmt::format("{:>10} {:>10} {:>12} {:>12}", row.n,
                                   row.contacts >= 0 ? row.contacts : row.bullet_contacts,
                                   num(row.bullet_scratch_s, "{:.4g}"), num(row.bullet_warm_s, "{:.4g}"));
    for (Backend b : backends) {
      auto it = row.engine_s.find(b);
      const double e = it == row.engine_s.end() ? -1 : it->second;
      line += fmt::format(" {:>12} {:>9} {:>9}", num(e, "{:.4g}"),
                          num(e > 0 && row.bullet_scratch_s >= 0 ? row.bullet_scratch_s / e : -1, "{:.1f}"),
                          num(e > 0 && row.bullet_warm_s >= 0 ? row.bullet_warm_s / e : -1, "{:.1f}"));
    }
    line += fmt::format(" {:>6}", row.compared ? (row.agree ? "yes" : "NO") : "-");
    out << line << '\n';
  }
}

}  // namespace

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
      "bench: N = 2^{} … 2^{} (Bullet double to 2^{}, engine {} to 2^{}), {} repetitions, "
      "seed {}\n",
      o.lo, hi, o.bullet_hi, to_string(o.precision), o.engine_hi, o.repetitions, o.seed);
  for (int e = o.lo; e <= hi; ++e) {
    BenchRow row;
    row.n = std::uint64_t(1) << e;
    GenerateOptions g;
    g.kind = "uniform";
    g.count = row.n;
    g.seed = o.seed + std::uint64_t(e);
    g.radius_low = o.radius_low;
    g.radius_high = o.radius_high;
    g.contacts_per_body = o.contacts_per_body;
    const Scene scene = generate_scene(g);

    if (e <= o.engine_hi) {
      const BodiesView view{scene.sphere_position, scene.sphere_radius, {}, {}};
      for (Backend b : backends) {
        EngineOptions eo;
        eo.backend = b;
        eo.threads = o.threads;
        eo.fp32_broad_phase = o.precision == Precision::mixed;
        std::int64_t count = 0;
        std::vector<double> times;
        auto time_engine = [&](auto real) {
          Engine<decltype(real)> engine(eo);
          count = std::int64_t(engine.detect(view).size());  // warm-up, untimed
          for (int r = 0; r < o.repetitions; ++r) {
            const auto t0 = Clock::now();
            const auto c = engine.detect(view);
            times.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
            if (std::int64_t(c.size()) != count)
              throw Error(fmt::format("bench: engine ({}) gave {} then {} contacts at N = {}", to_string(b),
                                      count, c.size(), row.n));
          }
        };
        if (o.precision == Precision::fp32)
          time_engine(float{});
        else
          time_engine(double{});
        row.engine_s[b] = median(times);
        row.engine_contacts[b] = count;
        if (row.contacts < 0) row.contacts = count;
      }
    }
    if (e <= o.bullet_hi) {
      OracleBodies s;
      s.position.assign(scene.sphere_position.begin(), scene.sphere_position.end());
      s.radius.assign(scene.sphere_radius.begin(), scene.sphere_radius.end());
      s.id.resize(scene.sphere_count());
      for (std::size_t i = 0; i < s.id.size(); ++i) s.id[i] = std::int64_t(i);
      const OracleResult br = bullet_collide(s, Precision::fp64, /*warm_step=*/true);
      row.bullet_contacts = std::int64_t(br.contacts.size());
      row.bullet_scratch_s = br.scratch_seconds;
      row.bullet_warm_s = br.warm_seconds;
    }
    std::vector<std::int64_t> counts;
    for (const auto& [b, c] : row.engine_contacts) counts.push_back(c);
    if (row.bullet_contacts >= 0) counts.push_back(row.bullet_contacts);
    row.compared = counts.size() >= 2;
    row.agree =
        row.compared && std::all_of(counts.begin(), counts.end(), [&](auto c) { return c == counts[0]; });
    result.rows.push_back(row);
    out << fmt::format("  N = 2^{}: done", e);
    if (row.bullet_scratch_s >= 0) out << fmt::format(" (Bullet {:.3g} s)", row.bullet_scratch_s);
    out << '\n' << std::flush;
  }

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
  print_table(result, backends, out);
  out << "log-log slopes (N >= 2^14):";
  for (const auto& [name, s] : result.slopes)
    out << fmt::format("  {} {}", name, std::isnan(s) ? std::string("-") : fmt::format("{:.3f}", s));
  out << '\n';

  result.csv_path = o.csv;
  write_csv(o.csv, csv_lines(result));
  out << "wrote " << o.csv << '\n';

  if (o.plot) {
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
