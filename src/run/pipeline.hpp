#pragma once
// The `detect` command (detect_command.cpp): the stages of a run sequenced in pipeline.cpp
// (distributed_run.hpp), then the write and the summary:
//   read → frame → slabs → distribute → exchange ghosts → detect → collect contacts → write → summary
#include <optional>
#include <string>

#include "precision_choice.hpp"
#include "run/distributed_detect.hpp"
#include "session.hpp"

namespace cg {

struct DetectCommand {
  std::string input;
  std::string output;
  std::string csv;  // optional text copy
  Backend backend = Backend::automatic;
  std::optional<Precision> precision;  // --precision; empty: auto (the default), chosen by accuracy
  Accuracy accuracy;                   // --accuracy (auto only; unset: fp64's, docs/PRECISION.md)
  Fields fields = Fields::basic;
  double cell_size = 0;                            // 0: chosen by cell_choice
  CellChoice cell_choice = CellChoice::tuned;      // --cell-size auto | min
  BroadPhase broad_phase = BroadPhase::automatic;  // --broad-phase
  int threads = 0;
  double solver_tolerance = 0;  // EngineOptions::ellipsoid_tolerance (--solver-tolerance; 0: default)
  int solver_iterations = 0;    // EngineOptions::ellipsoid_max_iterations (--solver-iterations; 0: default)
  SlabAxis axis = SlabAxis::automatic;
  Balance balance = Balance::count;
  SceneRead read = SceneRead::automatic;
  ContactOutput write = ContactOutput::gather;
  int steps = 0;            // resident steps after the run (a simulation's per-step cost)
  double skin = 0;          // EngineOptions::skin: candidates kept across the resident steps
  bool skin_auto = false;   // --skin auto: EngineOptions::skin_auto
  double spin = 0;          // StepMotion::spin: radians per step the ellipsoids turn in the resident steps
  double drift = 0;         // StepMotion::drift: world length per step every centre moves
  std::string final_scene;  // --final-scene: the last step's bodies as a scene file
  std::uint64_t max_pair_tests = 0;  // EngineOptions::max_pair_tests (0: no limit)
  std::uint64_t memory_limit = 0;    // --memory-limit: device bytes per rank, pieces (0: one piece)
  bool quiet = false;
  bool xdmf = false;     // --xdmf: ParaView files beside the output (src/cli, io/xdmf)
  bool verbose = false;  // also the info lines of the run (the merge line with its duplicate count)
};

// Runs one detection over all ranks of `session`; returns the process exit code (0). Rank 0 writes the
// output file (--write ranks: every rank writes its rows of it); the summary comes from rank 0. Errors are
// agreed on by all ranks and thrown on every rank. Before the scene is read, every rank that will write
// checks that its output files' directories exist and are writable (IoError naming the directory).
int run_detect(const DetectCommand& cmd, Session& session);

}  // namespace cg
