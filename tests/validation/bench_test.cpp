// Tests of `contactgrid bench` (src/bench/bench.hpp) on tiny N: the CSV has the documented columns, one
// row per N, contact counts that agree with Bullet; and the log-log slope fit.
#include "bench/bench.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace cg {
namespace {

namespace fs = std::filesystem;

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  std::string f;
  while (std::getline(ss, f, ',')) out.push_back(f);
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

TEST(Bench, TinyRunWritesCsvWithExpectedColumns) {
  const fs::path dir = fs::temp_directory_path() / ("cg_bench_test_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  BenchOptions o;
  o.lo = 8;
  o.bullet_hi = 10;
  o.engine_hi = 10;
  o.repetitions = 1;
  o.backends = {Backend::cpu};
  o.csv = (dir / "bench.csv").string();
  o.plot = true;  // plots when gnuplot is on PATH, else prints how
  std::ostringstream log;
  const BenchResult r = run_bench(o, log);
  ASSERT_EQ(r.rows.size(), 3u) << log.str();

  std::ifstream f(o.csv);
  std::string line;
  ASSERT_TRUE(std::getline(f, line));
  const std::vector<std::string> expected{"n",
                                          "log2n",
                                          "contacts",
                                          "bullet_contacts",
                                          "agree",
                                          "bullet_scratch_s",
                                          "bullet_warm_s",
                                          "engine_cpu_s",
                                          "engine_cuda_s",
                                          "speedup_cpu_vs_scratch",
                                          "speedup_cpu_vs_warm",
                                          "speedup_cuda_vs_scratch",
                                          "speedup_cuda_vs_warm"};
  EXPECT_EQ(split(line), expected);
  int rows = 0;
  while (std::getline(f, line)) {
    const auto v = split(line);
    ASSERT_EQ(v.size(), expected.size()) << line;
    EXPECT_EQ(std::stoull(v[0]), 1ull << (8 + rows));
    EXPECT_EQ(v[2], v[3]) << "engine and Bullet contact counts: " << line;
    EXPECT_EQ(v[4], "yes");
    EXPECT_GT(std::stod(v[5]), 0.0);
    EXPECT_GT(std::stod(v[6]), 0.0);
    EXPECT_GT(std::stod(v[7]), 0.0);
    EXPECT_TRUE(v[8].empty());  // no CUDA asked
    EXPECT_GT(std::stod(v[9]), 0.0);
    ++rows;
  }
  EXPECT_EQ(rows, 3);
  EXPECT_NE(log.str().find("agree"), std::string::npos);
  if (r.plotted) {
    for (const char* name : {"bench_time.png", "bench_time.svg", "bench_loglog.png", "bench_loglog.svg"})
      EXPECT_TRUE(fs::exists(dir / name)) << name;
  }
  fs::remove_all(dir);
}

TEST(Bench, LogLogSlope) {
  std::vector<double> x, y;
  for (int e = 10; e <= 20; ++e)
    x.push_back(std::ldexp(1.0, e)), y.push_back(3e-7 * std::pow(x.back(), 1.25));
  EXPECT_NEAR(loglog_slope(x, y, std::ldexp(1.0, 14)), 1.25, 1e-12);
  EXPECT_TRUE(std::isnan(loglog_slope(x, y, std::ldexp(1.0, 20))));  // one point only
}

TEST(Bench, BadOptionsThrow) {
  BenchOptions o;
  o.lo = 0;
  EXPECT_THROW(run_bench(o), UsageError);
  o.lo = 10;
  o.repetitions = 0;
  EXPECT_THROW(run_bench(o), UsageError);
}

}  // namespace
}  // namespace cg
