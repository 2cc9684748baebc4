// Sequencing of a contactgrid run. Reads like the data flow; each stage is one call.
#include "pipeline.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "distributed_detect.hpp"
#include "distributed_write.hpp"
#include "hdf5_io.hpp"
#include "session.hpp"
#include "slab_decomposition.hpp"

namespace cg {
namespace {

using clock_type = std::chrono::steady_clock;
double seconds_since(clock_type::time_point t) {
  return std::chrono::duration<double>(clock_type::now() - t).count();
}

template <class Real>
void print_summary(const RunInfo& info, std::uint64_t contacts, const DistributedResult<Real>& r) {
  fmt::print("contactgrid detect: {} bodies, {} contacts ({:.3f} per body), {} rank(s), backend {}, {}\n",
             info.bodies, contacts, info.bodies ? double(contacts) / double(info.bodies) : 0.0, info.ranks,
             info.backend, info.precision);
  fmt::print("  cell size {:.6g}", info.cell_size);
  if (r.ranks > 1)
    fmt::print(", read {}, slab axis {}, owned bodies per rank {} … {}, ghosts {}, duplicates removed {}",
               r.read == SceneRead::every_row ? "all rows per rank" : "own rows", "xyz"[r.axis], r.owned_min,
               r.owned_max, r.ghosts, r.duplicates_removed);
  fmt::print("\n  {}-bit cell keys, {} (cell, body) entries, {} pair tests; times: maximum over ranks\n",
             r.stats.key_bits, r.stats.entries, r.stats.pair_tests);
  double total = 0;
  fmt::print("  {:<16} {:>12}\n", "stage", "seconds");
  for (const auto& t : info.times) {
    const bool sub = t.name.rfind("detect.", 0) == 0;  // the engine's stages, inside "detect"
    if (!sub) total += t.seconds;
    fmt::print("  {:<16} {:>12.6f}\n", sub ? "  " + t.name.substr(7) : t.name, t.seconds);
  }
  fmt::print("  {:<16} {:>12.6f}\n", "total", total);
  if (r.steps.steps > 0) {
    const StepStats& s = r.steps;
    fmt::print(
        "resident steps: {} (bodies kept in each rank's engine), {} contacts per step (= the file's), {} "
        "ghost "
        "rows refreshed per step; setup {:.6f} s; per step, median of the maxima over ranks:\n",
        s.steps, s.contacts, s.halo_rows, s.setup);
    fmt::print("  {:<16} {:>12.6f}\n  {:<16} {:>12.6f}\n", "halo", s.halo, "interior", s.interior);
    for (const StageTime& t : s.stages) fmt::print("    {:<14} {:>12.6f}\n", t.name, t.seconds);
    fmt::print("  {:<16} {:>12.6f}\n  {:<16} {:>12.6f}\n", "boundary", s.boundary, "step", s.step);
  }
}

template <class Real>
int detect(const DetectCommand& cmd, Session& session) {
  DistributedOptions o;
  o.engine.backend = cmd.backend;
  o.engine.fields = cmd.fields;
  o.engine.cell_size = cmd.cell_size;
  o.engine.cell_choice = cmd.cell_choice;
  o.engine.threads = cmd.threads;
  if (cmd.backend != Backend::cpu) o.engine.device = session.device_for(cuda_device_count());
  o.axis = parse_axis(cmd.axis);
  o.balance = parse_balance(cmd.balance);
  o.read = cmd.read == "all"   ? SceneRead::every_row
           : cmd.read == "own" ? SceneRead::own_rows
                               : SceneRead::automatic;
  if (!cmd.quiet && session.rank() == 0) o.log = [](const std::string& line) { fmt::print("{}\n", line); };
  // The design card's shape by default: rank 0 gathers, deduplicates and writes the sorted contacts
  // (--write gather). --write ranks: each rank keeps the contacts of its id_a range and writes them
  // into the one output file. A CSV copy is written by rank 0 alone, so it always gathers.
  o.output = cmd.write == "ranks" && cmd.csv.empty() ? ContactOutput::id_ranges : ContactOutput::root;
  o.resident_steps = cmd.steps;

  // read → slabs → redistribute (or, reading every row, select) → halo → engine → gather to rank 0
  // (or exchange by id_a range) → merge (comm/distributed_detect.cpp; with one rank: read → engine)
  DistributedResult<Real> r = distributed_detect<Real>(session, cmd.input, o);

  RunInfo info;
  info.bodies = r.bodies;
  info.precision = to_string(cmd.precision);
  info.backend = to_string(r.backend);
  info.ranks = r.ranks;
  info.cell_size = r.cell_size;
  info.input = cmd.input;
  info.times = r.times;
  // every rank writes its rows of the one file (comm/distributed_write.hpp); adds the "write" time
  write_contacts_distributed(session, cmd.output, r.contacts, r.first_row, r.total_contacts, info, r.threads);
  if (!cmd.csv.empty()) {
    std::exception_ptr error;
    if (session.rank() == 0) {
      try {
        auto t = clock_type::now();
        write_contacts_csv(cmd.csv, r.contacts);
        info.times.push_back({"csv", seconds_since(t)});
      } catch (...) {
        error = std::current_exception();
      }
    }
    session.agree(error, "csv");
  }
  if (!cmd.quiet && session.rank() == 0) print_summary(info, r.total_contacts, r);
  return 0;
}

}  // namespace

int run_detect(const DetectCommand& cmd, Session& session) {
  if (cmd.output.empty()) throw UsageError("detect: -o/--output is required");
  return cmd.precision == Precision::fp32 ? detect<float>(cmd, session) : detect<double>(cmd, session);
}

int run_compare(const std::string& a, const std::string& b) {
  int differ = 0;
  for (const char* name : kContactDatasets) {
    const std::string ds = name;
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
  generate_scene_file(path, options);
  if (!quiet)
    fmt::print("contactgrid generate: {} {} bodies (seed {}) -> {} in {:.3f} s\n", options.count,
               options.kind, options.seed, path, seconds_since(t));
  return 0;
}

template <class Real>
void write_contacts_csv(const std::string& path, const Contacts<Real>& c) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  {
    std::FILE* f = std::fopen(tmp.c_str(), "w");
    if (!f) throw IoError(path + ": cannot open for writing");
    fmt::print(f,
               "id_a,id_b,position_on_a_x,position_on_a_y,position_on_a_z,position_on_b_x,position_on_b_y,"
               "position_on_b_z,normal_on_b_x,normal_on_b_y,normal_on_b_z,distance\n");
    for (std::size_t k = 0; k < c.size(); ++k) {
      const auto &pa = c.position_on_a[k], &pb = c.position_on_b[k], &n = c.normal_on_b[k];
      fmt::print(f, "{},{},{},{},{},{},{},{},{},{},{},{}\n", c.id_a[k], c.id_b[k], pa.x, pa.y, pa.z, pb.x,
                 pb.y, pb.z, n.x, n.y, n.z, c.distance[k]);
    }
    if (std::fclose(f) != 0) {
      std::filesystem::remove(tmp);
      throw IoError(path + ": write failed");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp);
    throw IoError(path + ": cannot rename temporary file: " + ec.message());
  }
}
template void write_contacts_csv(const std::string&, const Contacts<float>&);
template void write_contacts_csv(const std::string&, const Contacts<double>&);

}  // namespace cg
