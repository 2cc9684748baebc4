// The CPU backend's stages on one scene, in one process (not a test): REPETITIONS calls (after one
// warm call), each with a new engine as contactgrid.detect makes (`fresh`) or all with one engine
// (`reuse`: the engine's workspace kept between calls), and per stage the minimum and the median over
// the calls. On a loaded machine the minimum is the fairer figure (preemption only adds time); with
// THREADS 1 it compares builds without the other processes' share of the cores. "cpu" is the CPU
// time of the process over the call (user + system, all threads: getrusage), which other processes on
// the same cores do not inflate.
//   host_stage_bench SCENE.h5 [REPETITIONS=9] [THREADS=0] [PRECISION=mixed|fp32|fp64] [fresh|reuse]
// (CG_BENCH_CELL_SIZE=EDGE in the environment: the grid's cell edge, EngineOptions::cell_size)
// Prints one line per stage: name, min ms, median ms; then the CPU ms of a call ("cpu") and its minor
// page faults ("faults", a count: each fresh page the kernel zeroes); then contacts and the last call's
// stats (entries, pair tests, candidates, key bits, cell edge: the same on every path).
#include <sys/resource.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "engine.hpp"
#include "io/scene_file.hpp"

using namespace cg;

namespace {

double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

// Minor page faults of the process so far (a fresh page the kernel zeroes is one).
double page_faults() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_minflt);
}

template <class Real>
std::size_t calls(const EngineOptions& o, const BodiesView& v, int repetitions, bool reuse,
                  std::map<std::string, std::vector<double>>& stage_times, std::vector<std::string>& order,
                  EngineStats& stats) {
  std::unique_ptr<Engine<Real>> engine;
  std::size_t contacts = 0;
  for (int r = -1; r < repetitions; ++r) {
    if (!engine || !reuse) engine = std::make_unique<Engine<Real>>(o);
    const double cpu0 = cpu_seconds(), faults0 = page_faults();
    contacts = engine->detect(v).size();
    stats = engine->stats();
    const double cpu = cpu_seconds() - cpu0, faults = page_faults() - faults0;
    if (r < 0) continue;  // warm: the first call's page faults of the process
    double total = 0;
    for (const StageTime& t : engine->times()) {
      if (std::find(order.begin(), order.end(), t.name) == order.end()) order.push_back(t.name);
      stage_times[t.name].push_back(t.seconds);
      total += t.seconds;
    }
    stage_times["(sum)"].push_back(total);
    stage_times["cpu"].push_back(cpu);
    stage_times["faults"].push_back(faults * 1e-3);  // printed as a count: the rows print s × 1e3
  }
  order.push_back("(sum)");
  order.push_back("cpu");
  order.push_back("faults");
  return contacts;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s SCENE.h5 [REPETITIONS] [THREADS] [PRECISION] [fresh|reuse]\n", argv[0]);
    return 2;
  }
  const int repetitions = argc > 2 ? std::max(1, std::atoi(argv[2])) : 9;
  EngineOptions o;
  o.backend = Backend::cpu;
  o.threads = argc > 3 ? std::atoi(argv[3]) : 0;
  const std::string precision = argc > 4 ? argv[4] : "mixed";
  const bool reuse = argc > 5 && std::string(argv[5]) == "reuse";
  o.fp32_broad_phase = precision == "mixed";
  if (const char* cell = std::getenv("CG_BENCH_CELL_SIZE")) o.cell_size = std::atof(cell);  // 0: the plan's
  const BodyRows rows = body_rows(read_scene(argv[1]), false);
  const BodiesView v{rows.position, rows.radius, {}, {}};
  std::map<std::string, std::vector<double>> stage_times;
  std::vector<std::string> order;
  EngineStats stats;
  const std::size_t contacts = precision == "fp32"
                                   ? calls<float>(o, v, repetitions, reuse, stage_times, order, stats)
                                   : calls<double>(o, v, repetitions, reuse, stage_times, order, stats);
  std::printf("stage      min_ms  median_ms  (%d calls, %s engine, threads %d, %s)\n", repetitions,
              reuse ? "one" : "a new", o.threads, precision.c_str());
  for (const std::string& name : order) {
    std::vector<double> t = stage_times[name];
    std::sort(t.begin(), t.end());
    std::printf("%-9s %7.2f %10.2f\n", name.c_str(), t.front() * 1e3, t[t.size() / 2] * 1e3);
  }
  std::printf("contacts %zu\n", contacts);
  std::printf("stats entries %llu pair_tests %llu candidates %llu key_bits %d cell_size %g\n",
              static_cast<unsigned long long>(stats.entries),
              static_cast<unsigned long long>(stats.pair_tests),
              static_cast<unsigned long long>(stats.candidates), stats.key_bits, stats.cell_size);
  return 0;
}
