// The small commands of the executable: compare and generate (commands.hpp).
#include "cli/commands.hpp"

#include <fmt/format.h>

#include <string>

#include "contacts.hpp"
#include "io/inspect.hpp"
#include "timing.hpp"

namespace cg {
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
  const auto t = WallClock::now();
  generate_scene_file(path, options, !quiet);
  if (!quiet)
    fmt::print("contactgrid generate: {} {} bodies (seed {}) -> {} in {:.3f} s\n", options.count,
               options.kind, options.seed, path, seconds_since(t));
  return 0;
}

}  // namespace cg
