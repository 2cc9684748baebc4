#pragma once
// The run directory of contactgrid simulate (docs/FORMAT.md §6):
//   frame_<step>.h5     a scene file (§1 with §5's motion) of the bodies at that step, in id order,
//                       root attributes step, time and the run's parameters
//   contacts_<step>.h5  (--write-contacts) that step's contacts with the history fields (§2)
//   run.xdmf            an XDMF time series over the frames (ParaView), rewritten after each frame
//   log.csv             one row per logged step: step, time, kinetic, potential (gravity + elastic),
//                       contacts, rebuilds (candidate lists built so far), seconds per step
// Every file is written to a temporary name and renamed, so no frame is ever partly written. A run
// in progress or cut off says so: run.xdmf carries <Information Name="status" Value="running"> until
// finish() writes "complete", and log.csv ends with the line "# status: complete" only then (a
// failure writes "# status: failed: <why>").
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "dem.hpp"
#include "io/contact_file.hpp"
#include "scene/scene.hpp"

namespace cg {

struct LogRow {
  std::uint64_t step = 0;
  double time = 0;
  DemEnergies energy;
  std::uint64_t contacts = 0, rebuilds = 0;
  double seconds_per_step = 0;
};

class RunOutput {
 public:
  // Creates the directory (UsageError when it exists and is not empty) and log.csv's header.
  // `parameters` go into every frame's root attributes.
  RunOutput(const std::string& directory, Attributes parameters);
  ~RunOutput();
  RunOutput(const RunOutput&) = delete;
  RunOutput& operator=(const RunOutput&) = delete;

  // The frame of `step`: the bodies (spheres first, then ellipsoids, as in the scene) as a scene file.
  void frame(std::uint64_t step, double time, const DemBodies& bodies, std::size_t spheres);
  template <class Real>
  void contacts(std::uint64_t step, const Contacts<Real>& contacts, const RunInfo& info);
  void log(const LogRow& row);
  // The run finished: log.csv and run.xdmf say "complete".
  void finish();
  // The run failed: log.csv says why, run.xdmf stays "running" (incomplete).
  void fail(const std::string& why) noexcept;

  std::string path(const std::string& name) const { return m_dir + "/" + name; }
  static std::string frame_name(std::uint64_t step);
  static std::string contacts_name(std::uint64_t step);

 private:
  void write_xdmf(bool complete);
  std::string m_dir;
  Attributes m_parameters;
  std::FILE* m_log = nullptr;
  struct Frame {
    std::uint64_t step;
    double time;
    std::size_t spheres, ellipsoids;
  };
  std::vector<Frame> m_frames;
  bool m_done = false;
};

}  // namespace cg
