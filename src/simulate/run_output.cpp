// The run directory of contactgrid simulate (run_output.hpp).
#include "simulate/run_output.hpp"

#include <fmt/format.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "errors.hpp"
#include "io/scene_file.hpp"
#include "io/text_file.hpp"

namespace cg {

namespace fs = std::filesystem;

RunOutput::RunOutput(const std::string& directory, Attributes parameters)
    : m_dir(directory), m_parameters(std::move(parameters)) {
  std::error_code ec;
  if (fs::exists(m_dir, ec) && !fs::is_empty(m_dir, ec))
    throw UsageError(m_dir + ": the run directory exists and is not empty (choose another -o)");
  fs::create_directories(m_dir, ec);
  if (ec) throw IoError(m_dir + ": cannot create the run directory: " + ec.message());
  const std::string log = path("log.csv");
  m_log = std::fopen(log.c_str(), "w");
  if (!m_log) throw IoError(log + ": cannot open for writing: " + std::strerror(errno));
  fmt::print(m_log, "step,time,kinetic,potential,contacts,rebuilds,seconds_per_step\n");
  std::fflush(m_log);
  write_xdmf(false);
}

RunOutput::~RunOutput() {
  if (m_log) std::fclose(m_log);
}

std::string RunOutput::frame_name(std::uint64_t step) { return fmt::format("frame_{:08d}.h5", step); }
std::string RunOutput::contacts_name(std::uint64_t step) { return fmt::format("contacts_{:08d}.h5", step); }

void RunOutput::frame(std::uint64_t step, double time, const DemBodies& b, std::size_t spheres) {
  Scene scene;
  const std::size_t n = b.size();
  for (std::size_t i = 0; i < spheres; ++i) {
    scene.sphere_position.push_back(b.position[i]);
    scene.sphere_radius.push_back(b.radius[i]);
    scene.sphere_velocity.push_back(b.velocity[i]);
    scene.sphere_angular_velocity.push_back(b.angular_velocity[i]);
  }
  for (std::size_t i = spheres; i < n; ++i) {
    const Quat<double> q = b.orientation[i];
    scene.ellipsoid_position.push_back(b.position[i]);
    scene.ellipsoid_semi_axes.push_back(b.semi_axes[i]);
    scene.ellipsoid_orientation.push_back({q.w, q.x, q.y, q.z});
    scene.ellipsoid_velocity.push_back(b.velocity[i]);
    scene.ellipsoid_angular_velocity.push_back(b.angular_velocity[i]);
  }
  scene.attributes = m_parameters;
  scene.attributes["step"] = static_cast<std::int64_t>(step);
  scene.attributes["time"] = time;
  write_scene(path(frame_name(step)), scene);
  m_frames.push_back({step, time, spheres, n - spheres});
  write_xdmf(false);
}

template <class Real>
void RunOutput::contacts(std::uint64_t step, const Contacts<Real>& c, const RunInfo& info) {
  write_contacts(path(contacts_name(step)), c, info);
}
template void RunOutput::contacts(std::uint64_t, const Contacts<float>&, const RunInfo&);
template void RunOutput::contacts(std::uint64_t, const Contacts<double>&, const RunInfo&);

void RunOutput::log(const LogRow& r) {
  fmt::print(m_log, "{},{:.9g},{:.12g},{:.12g},{},{},{:.6g}\n", r.step, r.time, r.energy.kinetic,
             r.energy.potential(), r.contacts, r.rebuilds, r.seconds_per_step);
  if (std::fflush(m_log) != 0) throw IoError(path("log.csv") + ": cannot write: " + std::strerror(errno));
}

void RunOutput::finish() {
  fmt::print(m_log, "# status: complete\n");
  if (std::fflush(m_log) != 0) throw IoError(path("log.csv") + ": cannot write: " + std::strerror(errno));
  write_xdmf(true);
  m_done = true;
}

void RunOutput::fail(const std::string& why) noexcept {
  if (m_done || !m_log) return;
  std::string line = why;
  for (char& ch : line)
    if (ch == '\n') ch = ' ';
  fmt::print(m_log, "# status: failed: {}\n", line);
  std::fflush(m_log);
}

// One Grid per frame and body kind (spheres, ellipsoids: a spatial collection per time), the bodies
// as poly-vertices with their attributes read from the frame's datasets.
void RunOutput::write_xdmf(bool complete) {
  std::string x;
  x += "<?xml version=\"1.0\" ?>\n<Xdmf Version=\"3.0\">\n <Domain>\n";
  x += fmt::format("  <Information Name=\"status\" Value=\"{}\"/>\n", complete ? "complete" : "running");
  x += "  <Grid Name=\"run\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
  auto item = [](const std::string& file, const std::string& dataset, std::size_t rows, int cols) {
    const std::string dims = cols > 1 ? fmt::format("{} {}", rows, cols) : fmt::format("{}", rows);
    return fmt::format(
        "      <DataItem Dimensions=\"{}\" NumberType=\"Float\" Precision=\"8\" "
        "Format=\"HDF\">{}:{}</DataItem>\n",
        dims, file, dataset);
  };
  for (const Frame& f : m_frames) {
    const std::string file = frame_name(f.step);
    x += "   <Grid GridType=\"Collection\" CollectionType=\"Spatial\">\n";
    x += fmt::format("    <Time Value=\"{:.9g}\"/>\n", f.time);
    for (int kind = 0; kind < 2; ++kind) {
      const std::size_t rows = kind == 0 ? f.spheres : f.ellipsoids;
      if (rows == 0) continue;
      const std::string g = kind == 0 ? "/spheres" : "/ellipsoids";
      x += fmt::format("    <Grid Name=\"{}\" GridType=\"Uniform\">\n", kind == 0 ? "spheres" : "ellipsoids");
      x += fmt::format(
          "     <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"{}\" NodesPerElement=\"1\"/>\n",
          rows);
      x += "     <Geometry GeometryType=\"XYZ\">\n" + item(file, g + "/position", rows, 3) +
           "     </Geometry>\n";
      auto attribute = [&](const char* name, const char* type, const std::string& ds, int cols) {
        x += fmt::format("     <Attribute Name=\"{}\" AttributeType=\"{}\" Center=\"Node\">\n", name, type);
        x += item(file, ds, rows, cols);
        x += "     </Attribute>\n";
      };
      if (kind == 0) {
        attribute("radius", "Scalar", g + "/radius", 1);
      } else {
        attribute("semi_axes", "Vector", g + "/semi_axes", 3);
        attribute("orientation", "Matrix", g + "/orientation", 4);
      }
      attribute("velocity", "Vector", g + "/velocity", 3);
      attribute("angular_velocity", "Vector", g + "/angular_velocity", 3);
      x += "    </Grid>\n";
    }
    x += "   </Grid>\n";
  }
  x += "  </Grid>\n </Domain>\n</Xdmf>\n";
  write_text_file(path("run.xdmf"), x);
}

}  // namespace cg
