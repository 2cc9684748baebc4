// The C++ side of tests/bench/python_bench.py: the call contactgrid.detect(positions, radii, ...) makes,
// made from C++ on the same scene file, timed the same way (median wall time of repeated calls, each
// with a new engine, the precision chosen per call as precision "auto" does). Not a test.
//   detect_call_bench SCENE.h5 [REPETITIONS=5] [THREADS=0] [PRECISION=auto|fp32|fp64|mixed] [BACKEND=cpu]
// Prints: precision, contacts, the median and every time in seconds.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "engine.hpp"
#include "io/scene_file.hpp"
#include "precision_choice.hpp"

using namespace cg;

namespace {

struct Call {
  Precision mode;
  std::size_t contacts;
};

template <class Real>
std::size_t run(const EngineOptions& o, const BodiesView& v, const std::optional<Bounds>& b) {
  Engine<Real> engine(o);
  return (b ? engine.detect(v, *b) : engine.detect(v)).size();
}

// What contactgrid.detect does with NumPy input once the arrays are views: precision (auto: bounds →
// choose_precision), an engine of that mode, one detection.
Call detect_call(const BodiesView& v, std::optional<Precision> fixed, Backend backend, int threads) {
  EngineOptions o;
  o.backend = backend;
  o.threads = threads;
  Precision mode = fixed.value_or(Precision::fp64);
  std::optional<Bounds> b;  // auto: the bounds the mode is chosen from, which the engine then takes
  if (!fixed) {
    b = compute_bounds(v);
    mode = choose_precision(precision_scene(*b, false, 0, CellChoice::tuned), backend, {}).mode;
    const char* again = std::getenv("CONTACTGRID_AUTO_BOUNDS");  // as the module: "engine" the former path
    if (again != nullptr && std::string(again) == "engine") b.reset();
  }
  o.fp32_broad_phase = mode == Precision::mixed;
  return {mode, mode == Precision::fp32 ? run<float>(o, v, b) : run<double>(o, v, b)};
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s SCENE.h5 [REPETITIONS] [THREADS] [PRECISION] [BACKEND]\n", argv[0]);
    return 2;
  }
  const int repetitions = argc > 2 ? std::atoi(argv[2]) : 5;
  const int threads = argc > 3 ? std::atoi(argv[3]) : 0;
  const std::string word = argc > 4 ? argv[4] : "auto";
  const Backend backend = argc > 5 && std::string(argv[5]) == "cuda" ? Backend::cuda : Backend::cpu;
  std::optional<Precision> fixed;
  if (word == "fp32") fixed = Precision::fp32;
  if (word == "fp64") fixed = Precision::fp64;
  if (word == "mixed") fixed = Precision::mixed;

  const BodyRows rows = body_rows(read_scene(argv[1]), false);
  const BodiesView v{rows.position, rows.radius, {}, {}};
  detect_call(v, fixed, backend, threads);  // warm: page faults of the first allocations
  std::vector<double> times;
  Call call{};
  for (int r = 0; r < repetitions; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    call = detect_call(v, fixed, backend, threads);
    times.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  std::vector<double> sorted = times;
  std::sort(sorted.begin(), sorted.end());
  std::printf("precision %s contacts %zu median %.6f times", to_string(call.mode), call.contacts,
              sorted[sorted.size() / 2]);
  for (double t : times) std::printf(" %.6f", t);
  std::printf("\n");
  return 0;
}
