// The small commands of the executable (pipeline.hpp declares them): compare and generate.
#include <fmt/format.h>

#include <chrono>
#include <string>

#include "io/contact_file.hpp"
#include "io/inspect.hpp"
#include "io/scene_file.hpp"
#include "run/pipeline.hpp"

namespace cg {
namespace {
using clock_type = std::chrono::steady_clock;
double seconds_since(clock_type::time_point t) {
  return std::chrono::duration<double>(clock_type::now() - t).count();
}
}  // namespace

int run_compare(const std::string& a, const std::string& b) {
  int differ = 0;
  for (const ContactField& field : kContactFields) {
    const std::string ds = field.path;
    const auto ia = inspect_dataset(a, ds), ib = inspect_dataset(b, ds);
    if (!ia && !ib) continue;
    if (!ia || !ib) {
      fmt::print("{}: only in {}\n", ds, ia ? a : b);
      differ = 1;
      continue;
    }
    if (ia->type != ib->type || ia->dims != ib->dims) {
      fmt::print("{}: type or shape differ ({} vs {})\n", ds, ia->type, ib->type);
      differ = 1;
      continue;
    }
    const auto da = read_dataset_bytes(a, ds), db = read_dataset_bytes(b, ds);
    if (da != db) {
      std::size_t k = 0;
      while (k < da.size() && da[k] == db[k]) ++k;
      fmt::print("{}: differs from byte {} of {}\n", ds, k, da.size());
      differ = 1;
    }
  }
  fmt::print("{}: /contacts of {} and {}\n", differ ? "DIFFERENT" : "IDENTICAL", a, b);
  return differ;
}

int run_generate(const std::string& path, const GenerateOptions& options, bool quiet) {
  auto t = clock_type::now();
  generate_scene_file(path, options, !quiet);
  if (!quiet)
    fmt::print("contactgrid generate: {} {} bodies (seed {}) -> {} in {:.3f} s\n", options.count,
               options.kind, options.seed, path, seconds_since(t));
  return 0;
}

}  // namespace cg
