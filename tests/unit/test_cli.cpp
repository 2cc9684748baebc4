// End-to-end tests of the contactgrid executable: exit codes, messages and the no-partial-output rule.
// Exit codes (docs/USAGE.md): 0 ok, 1 validation FAIL, 2 usage, 3 bad input, 4 CUDA, 5 MPI, 6 I/O,
// 7 out of memory, 8 internal.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "engine.hpp"
#include "io/contact_file.hpp"
#include "io/scene_file.hpp"
#include "resident_steps.hpp"
#include "run/distributed_detect.hpp"
#include "run/pipeline.hpp"
#include "support/paths.hpp"
#include "support/run_cli.hpp"
#include "temp_dir.hpp"

namespace fs = std::filesystem;

namespace cg::test {
namespace {

using Result = CliResult;
Result run(const std::string& args) { return run_cli(args); }

class Cli : public TempDirTest {
 protected:
  // A detect run that must fail with `code`, a message containing every `needle`, and no output.
  void expect_detect_fails(const std::string& scene, int code, std::initializer_list<std::string> needles,
                           const std::string& extra = "") {
    const std::string out = path("out.h5");
    Result r = run("detect " + scene + " -o " + out + " " + extra);
    EXPECT_EQ(r.code, code) << r.output;
    for (const auto& n : needles)
      EXPECT_NE(r.output.find(n), std::string::npos) << "missing '" << n << "' in: " << r.output;
    EXPECT_FALSE(fs::exists(out)) << "a failed run left an output file";
    for (const auto& name : entries())
      EXPECT_EQ(name.find(".tmp"), std::string::npos) << "temporary left: " << name;
  }

  Scene small_scene(std::size_t n = 10) const {
    Scene s;
    for (std::size_t i = 0; i < n; ++i) {
      s.sphere_position.push_back({double(i) * 0.9, 0.25 * double(i % 3), 0});
      s.sphere_radius.push_back(0.5);
    }
    return s;
  }
};

// The ellipsoid solver's speed/accuracy knob on the command line: a looser tolerance makes fewer
// evaluations of f per run; a starved iteration cap is never silent (the summary counts the
// unconverged solves); a negative value is a usage error.
TEST_F(Cli, SolverToleranceAndIterationsReachTheSolver) {
  ASSERT_EQ(run("generate " + path("e.h5") + " --kind ellipsoids -n 3000 --seed 11 -q").code, 0);
  auto per_run = [](const std::string& out) {
    const auto at = out.find("runs, ");
    return at == std::string::npos ? -1.0 : std::stod(out.substr(at + 6));
  };
  auto unconverged = [](const std::string& out) {
    const auto at = out.find(" narrow solves unconverged");
    if (at == std::string::npos) return -1L;
    const auto from = out.rfind(' ', at - 1);
    return std::stol(out.substr(from + 1, at - from - 1));
  };
  const Result base =
      run("detect " + path("e.h5") + " -o " + path("d.h5") + " --backend cpu --precision fp64");
  const Result loose = run("detect " + path("e.h5") + " -o " + path("l.h5") +
                           " --backend cpu --precision fp64 --solver-tolerance 1e-3");
  const Result starved = run("detect " + path("e.h5") + " -o " + path("s.h5") +
                             " --backend cpu --precision fp64 --solver-iterations 2");
  ASSERT_EQ(base.code, 0) << base.output;
  ASSERT_EQ(loose.code, 0) << loose.output;
  ASSERT_EQ(starved.code, 0) << starved.output;
  EXPECT_GT(per_run(base.output), 0) << base.output;
  EXPECT_LT(per_run(loose.output), per_run(base.output)) << loose.output;
  EXPECT_EQ(unconverged(base.output), 0) << base.output;
  EXPECT_GT(unconverged(starved.output), 0) << starved.output;
  expect_detect_fails(path("e.h5"), 2, {"--solver-tolerance"}, "--backend cpu --solver-tolerance -1");
}

TEST_F(Cli, GenerateDetectRoundTrip) {
  Result g = run("generate " + path("s.h5") + " --count 3000 --seed 7 -q");
  ASSERT_EQ(g.code, 0) << g.output;
  Result d = run("detect " + path("s.h5") + " -o " + path("c.h5") + " --backend cpu --csv " + path("c.csv"));
  ASSERT_EQ(d.code, 0) << d.output;
  EXPECT_NE(d.output.find("3000 bodies"), std::string::npos) << d.output;
  EXPECT_NE(d.output.find("sort"), std::string::npos) << "per-stage times in the summary: " << d.output;
  ContactFile c = read_contacts(path("c.h5"));
  EXPECT_GT(c.contacts.size(), 3000u / 5);
  EXPECT_EQ(c.precision, "mixed");  // --precision auto, the default: fp64's answers, the cheapest on cpu
  std::ifstream csv(path("c.csv"));
  std::size_t lines = 0;
  for (std::string l; std::getline(csv, l);) ++lines;
  EXPECT_EQ(lines, c.contacts.size() + 1);
  // fp32 and full fields
  Result f = run("detect " + path("s.h5") + " -o " + path("c32.h5") +
                 " --backend cpu --precision fp32 --fields full -q");
  ASSERT_EQ(f.code, 0) << f.output;
  ContactFile c32 = read_contacts(path("c32.h5"));
  EXPECT_EQ(c32.precision, "fp32");
  EXPECT_TRUE(c32.contacts.full);
  EXPECT_EQ(c32.contacts.size(), c.contacts.size());
  // compare: the same run twice is byte-identical; fp64 and fp32 are not
  ASSERT_EQ(run("detect " + path("s.h5") + " -o " + path("c2.h5") + " --backend cpu --threads 1 -q").code, 0);
  Result same = run("compare " + path("c.h5") + " " + path("c2.h5"));
  EXPECT_EQ(same.code, 0) << same.output;
  EXPECT_NE(same.output.find("IDENTICAL"), std::string::npos) << same.output;
  EXPECT_EQ(run("compare " + path("c.h5") + " " + path("c32.h5")).code, 1);
}

// --precision mixed writes float64 datasets and the attribute "mixed", fp64's contacts byte for byte;
// fp32 refuses a 1e8 offset (its float32 positions would be 8 apart) with exit 3 and the reason.
TEST_F(Cli, MixedPrecisionAndFp32FarOffsetRefusal) {
  Result g = run("generate " + path("far.h5") + " --count 2000 --seed 5 --offset 1e8 1e8 1e8 -q");
  ASSERT_EQ(g.code, 0) << g.output;
  expect_detect_fails(path("far.h5"), 3, {"far.h5", "float32", "use --precision mixed or fp64"},
                      "--backend cpu --precision fp32");
  Result m = run("detect " + path("far.h5") + " -o " + path("m.h5") + " --backend cpu --precision mixed");
  ASSERT_EQ(m.code, 0) << m.output;
  EXPECT_NE(m.output.find("mixed"), std::string::npos) << m.output;
  ASSERT_EQ(
      run("detect " + path("far.h5") + " -o " + path("d.h5") + " --backend cpu --precision fp64 -q").code, 0);
  const ContactFile mixed = read_contacts(path("m.h5")), fp64 = read_contacts(path("d.h5"));
  EXPECT_EQ(mixed.precision, "mixed");
  EXPECT_GT(mixed.contacts.size(), 0u);
  Result same = run("compare " + path("m.h5") + " " + path("d.h5"));
  EXPECT_NE(same.output.find("IDENTICAL"), std::string::npos) << same.output;
}

// --max-aspect K: semi-axes U[Rhigh/K, Rhigh], so no ellipsoid is longer than 1:K (bench's scene).
TEST_F(Cli, GenerateMaxAspectBoundsTheEllipsoids) {
  ASSERT_EQ(run("generate " + path("e.h5") + " --kind ellipsoids -n 4000 --max-aspect 4 -q").code, 0);
  const Scene s = read_scene(path("e.h5"));
  ASSERT_EQ(s.ellipsoid_count(), 4000u);
  EXPECT_EQ(s.radius_low, 0.25);
  double widest = 1;
  for (const Vec3<double>& e : s.ellipsoid_semi_axes) {
    const double lo = std::min({e.x, e.y, e.z}), hi = std::max({e.x, e.y, e.z});
    EXPECT_GE(lo, 0.25);
    EXPECT_LE(hi, 1.0);
    widest = std::max(widest, hi / lo);
  }
  EXPECT_GT(widest, 3.5) << "4000 bodies reach close to 1:4";
  EXPECT_EQ(run("generate " + path("f.h5") + " --kind uniform -n 10 --max-aspect 4").code, 2);
  EXPECT_EQ(run("generate " + path("f.h5") + " --kind ellipsoids -n 10 --max-aspect 4 --rlow 0.1").code, 2);
  EXPECT_EQ(run("generate " + path("f.h5") + " --kind ellipsoids -n 10 --max-aspect 0.5").code, 2);
  EXPECT_FALSE(fs::exists(path("f.h5")));
}

TEST_F(Cli, PolydisperseUsesTheRatio) {
  ASSERT_EQ(run("generate " + path("p.h5") + " --kind polydisperse -n 5000 --ratio 100 -q").code, 0);
  const Scene s = read_scene(path("p.h5"));
  const auto [lo, hi] = std::minmax_element(s.sphere_radius.begin(), s.sphere_radius.end());
  EXPECT_GE(*lo, 0.01);
  EXPECT_LE(*hi, 1.0);
  EXPECT_GT(*hi / *lo, 50) << "log-uniform over a ratio of 100";
  EXPECT_EQ(run("generate " + path("q.h5") + " --kind polydisperse -n 10 --ratio 5000").code, 2);
}

// --broad-phase: every broad phase writes the same /contacts bytes; the summary names it; bench-broad
// prints its table and a CSV row per family, N and broad phase.
TEST_F(Cli, BroadPhasesWriteTheSameContacts) {
  ASSERT_EQ(
      run("generate " + path("i.h5") + " --kind intruders --intruders 3 --rhigh 1 --ratio 50 -n 3000 -q")
          .code,
      0);
  const Result a = run("detect " + path("i.h5") + " -o " + path("auto.h5") + " --backend cpu");
  ASSERT_EQ(a.code, 0) << a.output;
  EXPECT_NE(a.output.find("broad phase levels"), std::string::npos) << a.output;
  for (const char* bp : {"grid", "levels", "sweep", "brute"}) {
    const std::string out = path(std::string(bp) + ".h5");
    const Result d = run("detect " + path("i.h5") + " -o " + out + " --backend cpu --broad-phase " + bp);
    ASSERT_EQ(d.code, 0) << d.output;
    EXPECT_NE(d.output.find(std::string("broad phase ") + bp), std::string::npos) << d.output;
    EXPECT_EQ(run("compare " + path("auto.h5") + " " + out).code, 0) << bp;
  }
  EXPECT_EQ(run("detect " + path("i.h5") + " -o " + path("x.h5") + " --broad-phase tree").code, 2);
  ASSERT_EQ(
      run("generate " + path("b.h5") + " --kind bimodal --large-fraction 0.2 --ratio 10 -n 2000 -q").code, 0);
  EXPECT_EQ(read_scene(path("b.h5")).size(), 2000u);
  const Result b =
      run("bench-broad --lo 8 --hi 10 --families uniform,intruder1 --repetitions 1 --csv " + path("bb.csv"));
  ASSERT_EQ(b.code, 0) << b.output;
  EXPECT_NE(b.output.find("intruder1"), std::string::npos) << b.output;
  std::ifstream csv(path("bb.csv"));
  std::size_t lines = 0;
  for (std::string l; std::getline(csv, l);) ++lines;
  EXPECT_EQ(lines, 1u + 2 * 2 * 5) << "header + 2 families x N = 2^8, 2^10 x 5 broad phases";
  EXPECT_NE(b.output.find("auto within 10 % of the best: "), std::string::npos) << b.output;
  // --limit: at 2^10 every broad phase is predicted (from its time at 2^8) above 1 ns: skipped, shown
  // as ">t", and not in the CSV
  const Result lim = run("bench-broad --lo 8 --hi 10 --families uniform --repetitions 1 --limit 1e-9 --csv " +
                         path("lim.csv"));
  ASSERT_EQ(lim.code, 0) << lim.output;
  EXPECT_NE(lim.output.find(" >"), std::string::npos) << lim.output;
  std::ifstream lim_csv(path("lim.csv"));
  lines = 0;
  for (std::string l; std::getline(lim_csv, l);) ++lines;
  EXPECT_EQ(lines, 1u + 5) << "header + the 2^8 row's 5 broad phases";
  // --contacts-per-body: the families at a granular density (the generator's model: about 6 a body)
  const Result dense =
      run("bench-broad --lo 12 --hi 12 --families uniform --broad-phases grid --repetitions 1 "
          "--contacts-per-body 6 --csv " +
          path("dense.csv"));
  ASSERT_EQ(dense.code, 0) << dense.output;
  std::ifstream dense_csv(path("dense.csv"));
  std::string header, row;
  ASSERT_TRUE(std::getline(dense_csv, header) && std::getline(dense_csv, row)) << dense.output;
  std::vector<std::string> cells;
  for (std::size_t at = 0, next; at <= row.size(); at = next + 1) {
    next = std::min(row.find(',', at), row.size());
    cells.push_back(row.substr(at, next - at));
  }
  ASSERT_EQ(cells.size(), 10u) << row;  // family,n,log2n,broad_phase,ran,levels,seconds,contacts,…
  const double per_body = std::stod(cells[7]) / 4096.0;
  EXPECT_GT(per_body, 4.5) << row;
  EXPECT_LT(per_body, 7.5) << row;
}

TEST_F(Cli, ValidatePassesAndFails) {
  ASSERT_EQ(run("generate " + path("s.h5") + " --count 2000 --seed 3 -q").code, 0);
  ASSERT_EQ(run("detect " + path("s.h5") + " -o " + path("c.h5") + " --backend cpu -q").code, 0);
  Result ok = run("validate " + path("s.h5") + " " + path("c.h5"));
  EXPECT_EQ(ok.code, 0) << ok.output;
  EXPECT_NE(ok.output.find("PASS"), std::string::npos) << ok.output;
  // the same contacts against a different scene: refused (exit 3), saying so
  ASSERT_EQ(run("generate " + path("t.h5") + " --count 2000 --seed 4 -q").code, 0);
  Result bad = run("validate " + path("t.h5") + " " + path("c.h5"));
  EXPECT_EQ(bad.code, 3) << bad.output;
  EXPECT_NE(bad.output.find("not from " + path("t.h5")), std::string::npos) << bad.output;
  // a contact taken away: FAIL, exit 1
  Contacts<double> fewer = read_contacts(path("c.h5")).contacts;
  for (auto* v : {&fewer.position_on_a, &fewer.position_on_b, &fewer.normal_on_b}) v->pop_back();
  fewer.id_a.pop_back(), fewer.id_b.pop_back(), fewer.distance.pop_back();
  RunInfo info;
  info.precision = "fp64";
  write_contacts(path("fewer.h5"), fewer, info);
  Result fail = run("validate " + path("s.h5") + " " + path("fewer.h5"));
  EXPECT_EQ(fail.code, 1) << fail.output;
  EXPECT_NE(fail.output.find("FAIL missing: 1 pairs"), std::string::npos) << fail.output;
}

TEST_F(Cli, BenchWritesTheTable) {
  Result r = run("bench --lo 8 --bullet-hi 9 --engine-hi 10 --repetitions 1 --backend cpu --no-plot --csv " +
                 path("b.csv"));
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::exists(path("b.csv")));
  std::ifstream csv(path("b.csv"));
  std::size_t lines = 0;
  for (std::string l; std::getline(csv, l);) ++lines;
  EXPECT_EQ(lines, 4u) << "header + N = 2^8, 2^9, 2^10";
}

// `bench --kind ellipsoids|mixed` at tiny N: the documented CSV columns, one row per N, the engine
// against float Bullet with the exact ellipsoid support within float Bullet's shallow-miss rate
// (0.2–0.5 % measured, BENCHMARKS.md §8; allowed: 0.5 % plus three Poisson deviations, at least 3
// pairs), and the
// narrow-phase counters of the ellipsoid solve.
TEST_F(Cli, BenchEllipsoidAndMixedScenes) {
  auto split = [](const std::string& line) {
    std::vector<std::string> out;
    std::stringstream ss(line);
    for (std::string f; std::getline(ss, f, ',');) out.push_back(f);
    if (!line.empty() && line.back() == ',') out.emplace_back();
    return out;
  };
  const std::vector<std::string> columns{"n",
                                         "log2n",
                                         "kind",
                                         "ellipsoids",
                                         "contacts",
                                         "bullet_contacts",
                                         "agree",
                                         "bullet_scratch_s",
                                         "engine_cpu_s",
                                         "engine_cuda_s",
                                         "speedup_cpu_vs_scratch",
                                         "speedup_cuda_vs_scratch",
                                         "candidates",
                                         "narrow_hard",
                                         "narrow_fallbacks",
                                         "narrow_unconverged",
                                         "narrow_cpu_s",
                                         "narrow_cuda_s",
                                         "narrow_cpu_pairs_per_s",
                                         "narrow_cuda_pairs_per_s"};
  for (const std::string kind : {"ellipsoids", "mixed"}) {
    SCOPED_TRACE(kind);
    const std::string csv = path(kind + ".csv");
    Result r = run("bench --kind " + kind +
                   " --lo 9 --bullet-hi 10 --engine-hi 10 --repetitions 1 "
                   "--backend cpu --no-plot --csv " +
                   csv);
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_NE(r.output.find("float, exact ellipsoid support"), std::string::npos) << r.output;
    std::ifstream f(csv);
    std::string line;
    ASSERT_TRUE(std::getline(f, line));
    ASSERT_EQ(split(line), columns);
    auto col = [&](const std::vector<std::string>& v, const char* name) {
      return v[std::size_t(std::find(columns.begin(), columns.end(), name) - columns.begin())];
    };
    int rows = 0;
    while (std::getline(f, line)) {
      const auto v = split(line);
      ASSERT_EQ(v.size(), columns.size()) << line;
      const std::uint64_t n = std::stoull(col(v, "n"));
      EXPECT_EQ(n, 1ull << (9 + rows));
      EXPECT_EQ(col(v, "kind"), kind);
      EXPECT_EQ(std::stoull(col(v, "ellipsoids")), kind == "ellipsoids" ? n : n / 2) << line;
      const long long ours = std::stoll(col(v, "contacts")), bullet = std::stoll(col(v, "bullet_contacts"));
      EXPECT_GT(ours, std::int64_t(n) / 10) << line;
      const double misses = 0.005 * double(ours);  // float Bullet's shallow misses, expected
      const long long allowed =
          std::max(3LL, static_cast<long long>(std::ceil(misses + 3 * std::sqrt(misses))));
      EXPECT_LE(std::llabs(ours - bullet), allowed) << line;
      EXPECT_EQ(col(v, "agree"), "yes") << line;
      EXPECT_GT(std::stod(col(v, "bullet_scratch_s")), 0.0);
      EXPECT_GT(std::stod(col(v, "engine_cpu_s")), 0.0);
      EXPECT_TRUE(col(v, "engine_cuda_s").empty()) << "no CUDA asked for";
      EXPECT_GT(std::stod(col(v, "speedup_cpu_vs_scratch")), 0.0);
      const unsigned long long candidates = std::stoull(col(v, "candidates"));
      EXPECT_GE(candidates, static_cast<unsigned long long>(ours)) << "every contact was a candidate";
      // the generator's 0.4 per body is a density of bounding spheres, i.e. of the mixed scene's
      // candidates; of the ellipsoid scene's the centre cut (core/centre_cut.hpp) leaves about half
      if (kind == "mixed")
        EXPECT_NEAR(double(candidates) / double(n), 0.4, 0.1) << line;
      else
        EXPECT_LT(double(candidates) / double(n), 0.32) << line;
      EXPECT_LE(std::stoull(col(v, "narrow_hard")), candidates);
      EXPECT_LE(std::stoull(col(v, "narrow_fallbacks")), candidates);
      EXPECT_EQ(col(v, "narrow_unconverged"), "0") << "no pair misses the tolerance at aspect <= 1:4";
      EXPECT_GT(std::stod(col(v, "narrow_cpu_s")), 0.0);
      EXPECT_NEAR(std::stod(col(v, "narrow_cpu_pairs_per_s")) * std::stod(col(v, "narrow_cpu_s")),
                  double(candidates), 1e-3 * double(candidates))
          << line;
      EXPECT_TRUE(col(v, "narrow_cuda_pairs_per_s").empty());
      ++rows;
    }
    EXPECT_EQ(rows, 2);
  }
  // the options' bounds
  EXPECT_EQ(run("bench --kind cubes --no-plot --csv " + path("x.csv")).code, 2);
  EXPECT_EQ(run("bench --kind ellipsoids --max-aspect 0.5 --no-plot --csv " + path("x.csv")).code, 2);
  EXPECT_FALSE(fs::exists(path("x.csv")));
}

// --precision auto (the default): the cheapest mode whose documented bounds meet --accuracy for the
// scene, said in the summary (not with -q) and in the root attribute precision_choice; with no
// --accuracy, fp64's contacts byte for byte; an accuracy no mode meets exits 3 naming the scene.
TEST_F(Cli, PrecisionAutoPicksTheCheapestModeThatMeetsTheAccuracy) {
  ASSERT_EQ(run("generate " + path("s.h5") + " --count 3000 --seed 9 -q").code, 0);
  ASSERT_EQ(run("generate " + path("far.h5") + " --count 3000 --seed 9 --offset 1e6 1e6 1e6 -q").code, 0);
  auto detect = [&](const std::string& scene, const std::string& out, const std::string& extra) {
    return run("detect " + path(scene) + " -o " + path(out) + " --backend cpu " + extra);
  };
  // near the origin a lax accuracy takes fp32, and the file says why
  Result lax = detect("s.h5", "lax.h5", "--precision auto --accuracy 1e-2,0.1");
  ASSERT_EQ(lax.code, 0) << lax.output;
  EXPECT_NE(lax.output.find("precision auto: fp32, the cheapest on cpu that meets --accuracy 0.01,0.1°"),
            std::string::npos)
      << lax.output;
  const ContactFile f32 = read_contacts(path("lax.h5"));
  EXPECT_EQ(f32.precision, "fp32");
  EXPECT_EQ(std::get<std::string>(f32.attributes.at("precision_choice")).rfind("precision auto: fp32", 0),
            0u);
  Result quiet = detect("s.h5", "quiet.h5", "--accuracy 1e-2,0.1 -q");
  ASSERT_EQ(quiet.code, 0) << quiet.output;
  EXPECT_EQ(quiet.output.find("precision auto"), std::string::npos) << "-q silences it: " << quiet.output;
  // at 1e6 float32 positions are 0.11·r_min off: 1e-3 passes fp32 over, for mixed
  Result far = detect("far.h5", "far_auto.h5", "--accuracy 1e-3");
  ASSERT_EQ(far.code, 0) << far.output;
  EXPECT_NE(far.output.find("precision auto: mixed"), std::string::npos) << far.output;
  EXPECT_NE(far.output.find("fp32 gives position 0.109·r_min"), std::string::npos) << far.output;
  // no --accuracy: fp64's answers (mixed's are fp64's bit for bit); an explicit mode records no choice
  Result def = detect("far.h5", "def.h5", "");
  ASSERT_EQ(def.code, 0) << def.output;
  EXPECT_NE(def.output.find("precision auto: mixed, the cheapest on cpu that meets the default accuracy"),
            std::string::npos)
      << def.output;
  ASSERT_EQ(detect("far.h5", "fp64.h5", "--precision fp64 -q").code, 0);
  EXPECT_EQ(run("compare " + path("def.h5") + " " + path("fp64.h5")).code, 0);
  EXPECT_EQ(read_contacts(path("fp64.h5")).attributes.count("precision_choice"), 0u);
  // what no mode meets: exit 3, the scene named, what the best mode gives; and usage errors
  expect_detect_fails(path("far.h5"), 3, {"far.h5", "no precision mode meets --accuracy 1e-14", "fp64 gives"},
                      "--backend cpu --accuracy 1e-14");
  expect_detect_fails(path("s.h5"), 2, {"--accuracy", "only with --precision auto"},
                      "--precision fp32 --accuracy 1e-2");
  expect_detect_fails(path("s.h5"), 2, {"--accuracy", "'x' is not a number > 0"}, "--accuracy 1e-2,x");
  expect_detect_fails(path("s.h5"), 2, {"--precision"}, "--precision automatic");
}

TEST_F(Cli, UsageErrorsExitTwo) {
  write_scene(path("s.h5"), small_scene());
  EXPECT_EQ(run("detect " + path("s.h5") + " -o " + path("o.h5") + " --backend gpu").code, 2);
  EXPECT_EQ(run("detect " + path("s.h5") + " -o " + path("o.h5") + " --precision fp16").code, 2);
  EXPECT_EQ(run("detect " + path("s.h5")).code, 2);  // no output
  EXPECT_EQ(run("generate " + path("g.h5") + " --count 0").code, 2);
  EXPECT_EQ(run("bogus").code, 2);
  expect_detect_fails(path("s.h5"), 2, {"--cell-size"}, "--cell-size 0.5");  // smaller than the diameter
  // --cell-size takes auto, min or a length > 0; --read and --write their words
  expect_detect_fails(path("s.h5"), 2, {"--cell-size", "'wide' is not auto, min or a length > 0"},
                      "--cell-size wide");
  expect_detect_fails(path("s.h5"), 2, {"--cell-size", "'0' is not auto, min or a length > 0"},
                      "--cell-size 0");
  expect_detect_fails(path("s.h5"), 2, {"--cell-size"}, "--cell-size 3x");
  expect_detect_fails(path("s.h5"), 2, {"--read"}, "--read some");
  expect_detect_fails(path("s.h5"), 2, {"--axis"}, "--axis w");
  expect_detect_fails(path("s.h5"), 2, {"--balance"}, "--balance size");
  for (const char* typed : {"--axis x --balance width --read all --write ranks", "--axis z --read own",
                            "--axis auto --balance count --read auto --write gather"})
    EXPECT_EQ(run("detect " + path("s.h5") + " -o " + path("typed.h5") + " " + typed + " -q").code, 0)
        << typed;
  expect_detect_fails(path("s.h5"), 2, {"--write"}, "--write rank0");
  expect_detect_fails(path("s.h5"), 2, {"--steps"}, "--steps -1");
  expect_detect_fails(path("s.h5"), 2, {"--steps"}, "--steps many");
  EXPECT_EQ(run("detect " + path("s.h5") + " -o " + path("min.h5") + " --cell-size min -q").code, 0);
  EXPECT_EQ(run("detect " + path("s.h5") + " -o " + path("auto.h5") + " --cell-size auto -q").code, 0);
  // resident steps after the run: the summary says how many and that every one found the file's contacts
  const auto steps = run("detect " + path("s.h5") + " -o " + path("steps.h5") + " --backend cpu --steps 3");
  EXPECT_EQ(steps.code, 0) << steps.output;
  EXPECT_NE(steps.output.find("resident steps: 3 "), std::string::npos) << steps.output;
  EXPECT_NE(steps.output.find("contacts per step (= the file's)"), std::string::npos) << steps.output;
  // with a skin the steps reuse the candidates of the first (stage skin; the same contacts, checked)
  const auto skin =
      run("detect " + path("s.h5") + " -o " + path("skin.h5") + " --backend cpu --steps 3 --skin 0.1");
  EXPECT_EQ(skin.code, 0) << skin.output;
  EXPECT_NE(skin.output.find("contacts per step (= the file's)"), std::string::npos) << skin.output;
  EXPECT_NE(skin.output.find("    skin "), std::string::npos) << skin.output;
  EXPECT_EQ(steps.output.find("    skin "), std::string::npos) << steps.output;
  EXPECT_EQ(run("compare " + path("steps.h5") + " " + path("skin.h5")).code, 0);
  expect_detect_fails(path("s.h5"), 2, {"--skin"}, "--skin -0.5");
}

// Bodies that move (issue #31): --steps N --drift V writes the last step's contacts to -o and its
// bodies to --final-scene, whose plain detection writes the same /contacts bytes, with no skin, a fixed
// one and the automatic one (the summary says builds, reuses and the skin); the option errors, and a
// drift out of the mode's coordinate range refused before any step, naming the modes that hold it.
TEST_F(Cli, DriftingStepsWriteTheLastStep) {
  ASSERT_EQ(run("generate " + path("s.h5") + " -n 3000 --seed 13 --contacts-per-body 1 -q").code, 0);
  const std::string opts = " --backend cpu --precision fp64 --fields full";
  ASSERT_EQ(run("detect " + path("s.h5") + " -o " + path("file.h5") + opts + " -q").code, 0);
  for (const std::string skin : {"0", "0.15", "auto"}) {
    const auto r = run("detect " + path("s.h5") + " -o " + path("last.h5") + opts +
                       " --steps 6 --drift 0.05 --skin " + skin + " --final-scene " + path("final.h5"));
    ASSERT_EQ(r.code, 0) << skin << r.output;
    EXPECT_NE(r.output.find("the bodies drifting 0.05 per step"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("candidate lists: "), std::string::npos) << r.output;
    // the mean step, and the same without the frame (the drift's motion): positive, and not more
    double mean = 0, detection = 0;
    const std::size_t at = r.output.find("mean step ");
    ASSERT_NE(at, std::string::npos) << r.output;
    ASSERT_EQ(
        std::sscanf(r.output.c_str() + at, "mean step %lf s (without the frame %lf s)", &mean, &detection), 2)
        << r.output;
    EXPECT_GT(detection, 0) << r.output;
    EXPECT_LE(detection, mean) << r.output;
    if (skin == "auto") {
      EXPECT_NE(r.output.find(" (auto)"), std::string::npos) << r.output;
    }
    if (skin == "0.15") {  // builds and reuses: the stages of a building step too
      EXPECT_EQ(r.output.find(" 0 reuses"), std::string::npos) << r.output;
      EXPECT_NE(r.output.find("a building step's stages (s, median): plan "), std::string::npos) << r.output;
      EXPECT_NE(r.output.find(" pairs "), std::string::npos) << r.output;
    }
    if (skin == "0") {  // every step builds: the stage lines above are a building step's
      EXPECT_EQ(r.output.find("a building step's stages"), std::string::npos) << r.output;
    }
    ASSERT_EQ(run("detect " + path("final.h5") + " -o " + path("plain.h5") + opts + " -q").code, 0);
    EXPECT_EQ(run("compare " + path("last.h5") + " " + path("plain.h5")).code, 0) << "skin " << skin;
    EXPECT_EQ(run("compare " + path("file.h5") + " " + path("last.h5")).code, 1) << "the drift moved nothing";
  }
  expect_detect_fails(path("s.h5"), 2, {"--drift"}, "--backend cpu --steps 2 --drift inf");
  expect_detect_fails(path("s.h5"), 2, {"--drift", "--steps"}, "--backend cpu --drift 0.1");
  expect_detect_fails(path("s.h5"), 2, {"--final-scene", "--steps"}, "--final-scene " + path("f.h5"));
  expect_detect_fails(path("s.h5"), 2, {"--skin", "'fast' is not auto or a length >= 0"},
                      "--steps 2 --skin fast");
  expect_detect_fails(path("s.h5"), 3,
                      {"--drift", "out of the coordinate range of fp32", "use --precision mixed or fp64"},
                      "--backend cpu --precision fp32 --steps 2 --drift 1.5e6");
  expect_detect_fails(path("s.h5"), 3, {"--drift", "of fp64", "cell", "use --precision mixed"},
                      "--backend cpu --precision fp64 --steps 2 --drift 1e8");
  expect_detect_fails(path("s.h5"), 3, {"--drift", "no mode holds it"},
                      "--backend cpu --precision mixed --steps 2 --drift 1e308");
  EXPECT_FALSE(fs::exists(path("f.h5")));
}

// The resident steps on a mixed scene (issue #12): every step finds the file's contacts (the run checks
// the count and the pairs' hash per step, else exit 1), with and without a skin, and the file is the one
// a run without --steps writes.
TEST_F(Cli, ResidentStepsOnAMixedScene) {
  ASSERT_EQ(run("generate " + path("m.h5") +
                " -n 3000 --seed 9 --kind mixed --ellipsoid-fraction 0.4 --rlow 0.3 "
                "--rhigh 1 --contacts-per-body 1 -q")
                .code,
            0);
  const std::string opts = " --backend cpu --precision fp64 --fields full";
  ASSERT_EQ(run("detect " + path("m.h5") + " -o " + path("plain.h5") + opts + " -q").code, 0);
  for (const std::string extra : {"", " --skin 0.05"}) {
    const auto steps =
        run("detect " + path("m.h5") + " -o " + path("steps.h5") + opts + " --steps 3" + extra);
    EXPECT_EQ(steps.code, 0) << extra << steps.output;
    EXPECT_NE(steps.output.find("resident steps: 3 "), std::string::npos) << steps.output;
    EXPECT_NE(steps.output.find("contacts per step (= the file's)"), std::string::npos) << steps.output;
    EXPECT_EQ(run("compare " + path("plain.h5") + " " + path("steps.h5")).code, 0) << extra;
  }
  EXPECT_GT(read_contacts(path("plain.h5")).contacts.size(), 500u);  // the scene has contacts
  // --spin: the ellipsoids turn in the steps; the last step is checked against the turned bodies
  // detected from scratch (else exit 1), and the file stays the run's
  const auto spin = run("detect " + path("m.h5") + " -o " + path("spin.h5") + opts + " --steps 3 --spin 0.3");
  EXPECT_EQ(spin.code, 0) << spin.output;
  EXPECT_NE(spin.output.find("the ellipsoids turning 0.3 rad per step, "), std::string::npos) << spin.output;
  EXPECT_NE(spin.output.find("contacts on the last step (= the turned bodies detected from scratch)"),
            std::string::npos)
      << spin.output;
  EXPECT_EQ(run("compare " + path("plain.h5") + " " + path("spin.h5")).code, 0);
  expect_detect_fails(path("m.h5"), 2, {"--spin", "--steps"}, "--spin 0.3");  // --spin needs --steps
  expect_detect_fails(path("m.h5"), 2, {"--spin"}, "--steps 1 --spin inf");
}

// Stage times are typed; their names (the summary's rows, the contact file's attributes) are made once.
TEST(StageTimes, NamesOfTheSummaryAndTheFile) {
  const auto& engine = engine_stage_names();
  const auto pack = std::find(engine.begin(), engine.end(), "pack") - engine.begin();
  const RunTimes times{{RunStage::read, -1, 1.0},
                       {RunStage::detect, -1, 2.0},
                       {RunStage::detect, static_cast<int>(pack), 0.5},
                       {RunStage::exchange, -1, 0.25},
                       {RunStage::write, -1, 0.125}};
  const StageTimes file = file_stage_times(times);
  ASSERT_EQ(file.size(), times.size());
  const char* want[] = {"read", "detect", "detect.pack", "exchange", "write"};
  for (std::size_t k = 0; k < file.size(); ++k) {
    EXPECT_EQ(file[k].name, want[k]);
    EXPECT_EQ(file[k].seconds, times[k].seconds);
  }
  EXPECT_STREQ(stage_name(RunStage::redistribute), "redistribute");
  EXPECT_STREQ(stage_name(RunStage::csv), "csv");
}

TEST_F(Cli, MissingFile) { expect_detect_fails(path("nope.h5"), 3, {"nope.h5"}); }

TEST_F(Cli, NotAnHdf5File) {
  std::ofstream(path("text.h5")) << "this is not HDF5\n";
  expect_detect_fails(path("text.h5"), 3, {"text.h5"});
}

TEST_F(Cli, TruncatedFile) {
  write_scene(path("s.h5"), small_scene(5000));
  fs::resize_file(path("s.h5"), fs::file_size(path("s.h5")) / 2);
  expect_detect_fails(path("s.h5"), 3, {"s.h5"});
}

TEST_F(Cli, NoBodies) {
  write_scene(path("empty.h5"), Scene{});
  expect_detect_fails(path("empty.h5"), 3, {"empty.h5"});
}

TEST_F(Cli, NanCentreNamesDatasetAndRow) {
  Scene s = small_scene();
  s.sphere_position[6].y = std::nan("");
  write_scene(path("nan.h5"), s);
  expect_detect_fails(path("nan.h5"), 3, {"nan.h5", "/spheres/position", "6"});
}

TEST_F(Cli, InfiniteCentre) {
  Scene s = small_scene();
  s.sphere_position[2].z = INFINITY;
  write_scene(path("inf.h5"), s);
  expect_detect_fails(path("inf.h5"), 3, {"inf.h5", "/spheres/position", "2"});
}

TEST_F(Cli, NonPositiveRadius) {
  Scene s = small_scene();
  s.sphere_radius[4] = 0;
  write_scene(path("r0.h5"), s);
  expect_detect_fails(path("r0.h5"), 3, {"r0.h5", "/spheres/radius", "4"});
}

TEST_F(Cli, RadiusOutsidePromisedBounds) {
  Scene s = small_scene();
  s.radius_low = 0.4;
  s.radius_high = 0.6;
  s.sphere_radius[8] = 0.7;
  write_scene(path("rb.h5"), s);
  expect_detect_fails(path("rb.h5"), 3, {"rb.h5", "/spheres/radius", "8"});
}

TEST_F(Cli, UnwritableOutputIsAnIoError) {
  write_scene(path("s.h5"), small_scene());
  Result r = run("detect " + path("s.h5") + " -o " + path("no/such/dir/out.h5"));
  EXPECT_EQ(r.code, 6) << r.output;
  EXPECT_NE(r.output.find("cannot write into the directory " + path("no/such/dir") + ": it does not exist"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(path("no")));
}

// detect checks the output's directory before it reads the scene: with a scene that does not exist, a
// bad output directory is still the error (exit 6, naming the directory), not the missing scene (3).
// The same for a parent that is a file, an output that is a directory, and the --csv copy's directory.
TEST_F(Cli, OutputDirectoryIsCheckedBeforeTheScene) {
  const std::string absent = path("absent.h5");
  auto expect_io_error = [&](const std::string& args, const std::string& needle) {
    Result r = run("detect " + absent + " " + args);
    EXPECT_EQ(r.code, 6) << args << ": " << r.output;
    EXPECT_NE(r.output.find(needle), std::string::npos) << "missing '" << needle << "' in: " << r.output;
    EXPECT_EQ(r.output.find("absent.h5:"), std::string::npos) << "the scene was read first: " << r.output;
  };
  expect_io_error("-o " + path("missing/out.h5"),
                  "-o " + path("missing/out.h5") + ": cannot write into the directory " + path("missing"));
  std::ofstream(path("plain")) << "a file, not a directory\n";
  expect_io_error("-o " + path("plain/out.h5"),
                  "cannot write into the directory " + path("plain") + ": it is not a directory");
  fs::create_directory(path("taken.h5"));
  expect_io_error("-o " + path("taken.h5"), "-o " + path("taken.h5") + ": is a directory, not a file name");
  expect_io_error("-o " + path("ok.h5") + " --csv " + path("missing/c.csv"),
                  "--csv " + path("missing/c.csv") + ": cannot write into the directory " + path("missing"));
  EXPECT_FALSE(fs::exists(path("ok.h5")));
  // a writable directory lets the run go on to the scene, whose absence is then the error
  Result r = run("detect " + absent + " -o " + path("ok.h5"));
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("absent.h5"), std::string::npos) << r.output;
}

// The merge line (contacts merged, duplicates removed) is an info line of an MPI run: printed only
// with --verbose under mpirun (tests/cli/mpi_summary.sh), never by one rank, which merges nothing;
// --verbose with --quiet is a usage error.
TEST_F(Cli, MergeLineOnlyWhenVerbose) {
  write_scene(path("s.h5"), small_scene());
  const Result plain = run("detect " + path("s.h5") + " -o " + path("a.h5") + " --backend cpu");
  ASSERT_EQ(plain.code, 0) << plain.output;
  EXPECT_NE(plain.output.find("10 bodies"), std::string::npos) << plain.output;  // the summary is there
  EXPECT_EQ(plain.output.find("merge:"), std::string::npos) << plain.output;
  const Result verbose = run("detect " + path("s.h5") + " -o " + path("b.h5") + " --backend cpu --verbose");
  ASSERT_EQ(verbose.code, 0) << verbose.output;
  EXPECT_EQ(verbose.output.find("merge:"), std::string::npos) << verbose.output;
  EXPECT_EQ(run("compare " + path("a.h5") + " " + path("b.h5")).code, 0);
  expect_detect_fails(path("s.h5"), 2, {"--verbose", "--quiet"}, "-v -q");
}

// --help says what the tool is for (spheres and ellipsoids) and where the formats are written down;
// --version is CMake's project version, which is the first version of the changelog.
TEST_F(Cli, HelpAndVersion) {
  const Result help = run("--help");
  EXPECT_EQ(help.code, 0) << help.output;
  EXPECT_NE(help.output.find("spheres and ellipsoids"), std::string::npos) << help.output;
  EXPECT_NE(help.output.find("docs/FORMAT.md"), std::string::npos) << help.output;
  const Result version = run("--version");
  EXPECT_EQ(version.code, 0) << version.output;
  EXPECT_EQ(version.output, "contactgrid " CONTACTGRID_VERSION "\n");
  std::ifstream changelog(cg::test::source_dir() + "/docs/CHANGELOG.md");
  ASSERT_TRUE(changelog);
  std::string first;  // the first "## <version> ..." heading
  for (std::string line; first.empty() && std::getline(changelog, line);)
    if (line.rfind("## ", 0) == 0) first = line.substr(3, line.find(' ', 3) - 3);
  EXPECT_EQ(first, CONTACTGRID_VERSION) << "docs/CHANGELOG.md's first version";
}

TEST_F(Cli, CudaBackendWithoutGpuIsAClearError) {
  if (cuda_available()) GTEST_SKIP() << "a GPU is present";
  write_scene(path("s.h5"), small_scene());
  expect_detect_fails(path("s.h5"), 4, {"CUDA"}, "--backend cuda");
}

}  // namespace
}  // namespace cg::test
