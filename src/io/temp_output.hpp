#pragma once
// Every output of contactgrid is written to "<path>.tmp.<pid>" and renamed over <path> only once it
// is complete, so a failed or stopped run leaves no partial file. While it exists, the temporary is
// registered for removal should the process end at once (a signal: src/run/stop.hpp).
#include <string>

#include "run/stop.hpp"

namespace cg {

// "<path>.tmp.<pid of this process>"
std::string temp_name(const std::string& path);
// The directory an output file `path` goes into exists and is writable; else an IoError naming it
// (not the temporary name the file is first written under).
void check_output_directory(const std::string& path);
// Removes a file, ignoring errors. Never throws.
void remove_quietly(const std::string& file) noexcept;

// The temporary of one output: its directory checked (check_output_directory) and registered at
// construction; removed on destruction unless renamed over
// the path by commit(), which is the run's last stop point before the rename (a run asked to stop
// leaves no output).
class TempOutput {
 public:
  explicit TempOutput(std::string path);
  ~TempOutput();
  TempOutput(const TempOutput&) = delete;
  TempOutput& operator=(const TempOutput&) = delete;

  const std::string& path() const { return m_path; }
  const std::string& temp() const { return m_temp; }
  // Renames the temporary over the path (IoError naming both on failure; Stopped when a signal asked
  // the run to stop).
  void commit();

 private:
  std::string m_path, m_temp;
  CleanupAction m_cleanup;
  bool m_done = false;
};

}  // namespace cg
