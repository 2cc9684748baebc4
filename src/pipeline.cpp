// Sequencing of a contactgrid run. Reads like the data flow; each stage is one call.
#include "pipeline.hpp"

#include <fmt/format.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <unistd.h>

#include "hdf5_io.hpp"

namespace cg {
namespace {

using clock_type = std::chrono::steady_clock;
double seconds_since(clock_type::time_point t) {
  return std::chrono::duration<double>(clock_type::now() - t).count();
}

void print_summary(const RunInfo& info, std::uint64_t contacts, const EngineStats& stats) {
  fmt::print("contactgrid detect: {} bodies, {} contacts ({:.3f} per body), {} ranks, backend {}, {}\n",
             info.bodies, contacts, info.bodies ? double(contacts) / double(info.bodies) : 0.0, info.ranks,
             info.backend, info.precision);
  fmt::print("  cell size {:.6g}, {}-bit cell keys, {} (cell, body) entries, {} pair tests\n", info.cell_size,
             stats.key_bits, stats.entries, stats.pair_tests);
  double total = 0;
  for (const auto& t : info.times) total += t.seconds;
  fmt::print("  {:<12} {:>12}\n", "stage", "seconds");
  for (const auto& t : info.times) fmt::print("  {:<12} {:>12.6f}\n", t.name, t.seconds);
  fmt::print("  {:<12} {:>12.6f}\n", "total", total);
}

template <class Real>
int detect_single(const DetectCommand& cmd) {
  RunInfo info;
  info.input = cmd.input;
  info.precision = to_string(cmd.precision);
  auto t = clock_type::now();
  const Scene scene = read_scene(cmd.input);
  const double t_read = seconds_since(t);
  if (scene.ellipsoid_count() > 0)
    throw InputError(cmd.input + ": /ellipsoids: ellipsoids are not supported by this version yet");

  EngineOptions eo;
  eo.backend = cmd.backend;
  eo.fields = cmd.fields;
  eo.cell_size = cmd.cell_size;
  eo.threads = cmd.threads;
  Engine<Real> engine(eo);
  BodiesView bodies{scene.sphere_position, scene.sphere_radius, {}, {}};
  Contacts<Real> contacts;
  try {
    contacts = engine.detect(bodies);
  } catch (const InputError& e) {
    throw InputError(cmd.input + ": /spheres: " + e.what());
  }
  info.bodies = scene.size();
  info.backend = to_string(engine.backend());
  info.times.push_back({"read", t_read});
  for (const auto& st : engine.times()) info.times.push_back(st);
  {
    const Bounds b = compute_bounds(bodies);
    info.cell_size = cmd.cell_size > 0 ? cmd.cell_size
                                       : min_cell_size(b, sizeof(Real) == 4 ? Precision::fp32 : Precision::fp64);
  }
  t = clock_type::now();
  write_contacts(cmd.output, contacts, info);
  if (!cmd.csv.empty()) write_contacts_csv(cmd.csv, contacts);
  info.times.push_back({"write", seconds_since(t)});
  if (!cmd.quiet) print_summary(info, contacts.size(), engine.stats());
  return 0;
}

}  // namespace

int run_detect(const DetectCommand& cmd) {
  if (cmd.output.empty()) throw UsageError("detect: -o/--output is required");
  return cmd.precision == Precision::fp32 ? detect_single<float>(cmd) : detect_single<double>(cmd);
}

int run_generate(const std::string& path, const GenerateOptions& options, bool quiet) {
  auto t = clock_type::now();
  generate_scene_file(path, options);
  if (!quiet)
    fmt::print("contactgrid generate: {} {} bodies (seed {}) -> {} in {:.3f} s\n", options.count, options.kind,
               options.seed, path, seconds_since(t));
  return 0;
}

template <class Real>
void write_contacts_csv(const std::string& path, const Contacts<Real>& c) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  {
    std::FILE* f = std::fopen(tmp.c_str(), "w");
    if (!f) throw IoError(path + ": cannot open for writing");
    fmt::print(f, "id_a,id_b,position_on_a_x,position_on_a_y,position_on_a_z,position_on_b_x,position_on_b_y,"
                  "position_on_b_z,normal_on_b_x,normal_on_b_y,normal_on_b_z,distance\n");
    for (std::size_t k = 0; k < c.size(); ++k) {
      const auto &pa = c.position_on_a[k], &pb = c.position_on_b[k], &n = c.normal_on_b[k];
      fmt::print(f, "{},{},{},{},{},{},{},{},{},{},{},{}\n", c.id_a[k], c.id_b[k], pa.x, pa.y, pa.z, pb.x, pb.y,
                 pb.z, n.x, n.y, n.z, c.distance[k]);
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
