#pragma once
// A distributed run's read stage and the stages after it (run/pipeline.cpp), as the `detect` command
// (run/detect_command.cpp) and distributed_detect call them: the read first, so that --precision auto
// chooses the mode from the agreed bounds before the run in that mode.
#include <cstdint>
#include <string>

#include "assemble.hpp"
#include "grid_plan.hpp"
#include "host_vector.hpp"
#include "io/contact_file.hpp"
#include "run/distributed_detect.hpp"
#include "run/stop.hpp"
#include "session.hpp"

namespace cg {

// Rank r's partition of the scene: rows [part_first, part_first + part_count) = [N·r/P, N·(r+1)/P),
// read alone (own rows) or with every other row (every row: rows [0, N)); its bounds.
struct Partition {
  std::uint64_t bodies = 0;  // N
  std::uint64_t first = 0;   // row of position[0]
  std::uint64_t part_first = 0, part_count = 0;
  HostVector<Vec3<double>> position;
  HostVector<double> radius;  // the bounding radius
  ShapeRows shapes;           // the scene has ellipsoids: every row's shape rows; else empty
  bool has_shapes = false;    // the scene has ellipsoids (every rank agrees)
  std::uint64_t ellipsoids = 0;
  Bounds bounds;  // of the partition's rows (count 0: none)
};

// The read stage: the options checked before any communication, this rank's partition read, the global
// bounds all-gathered (every rank the same: what --precision auto chooses from), and its time.
struct ReadScene {
  Partition part;
  Bounds global;
  bool all_rows = false;
  double seconds = 0;
};

ReadScene read_scene(const Session& session, const std::string& path, const DistributedOptions& options);

// The stages frame … collect after the read stage, with their times (max over ranks) and the run's
// statistics. Called inside the rank's DefaultTeam of `threads`. Given a `stream` (one rank under a
// memory limit), each piece's rows are appended to the output file as they come.
template <class Real>
DistributedResult<Real> distributed_run(Session& session, const std::string& path,
                                        const DistributedOptions& options, ReadScene&& in, int threads,
                                        ContactFileStream* stream = nullptr);

// A failing MPI call (CommFailure) leaves other ranks possibly waiting in a collective this rank will
// never join: it ends the job (Session::abort, exit code 5), its registered temporaries removed first.
template <class F>
auto or_abort(Session& session, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const CommFailure& e) {
    run_cleanup_actions();
    session.abort(e.exit_code(), e.what());
  }
}

}  // namespace cg
