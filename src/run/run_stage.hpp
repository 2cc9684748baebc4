#pragma once
// The stages of a distributed run as timed (RunStage), and their times (RunTime): the names are the
// summary's rows and the contact file's time attributes (src/io/contact_file: RunInfo::times).
// The engine's own stages inside `detect` are kernels/stage.hpp's EngineStage, by name.
#include <string>
#include <vector>

#include "engine.hpp"

namespace cg {

// The stages of a run, as timed.
enum class RunStage { read, redistribute, halo, detect, gather, exchange, merge, write, csv };
const char* stage_name(RunStage stage);

// One stage's time (maximum over ranks). engine_stage >= 0: the engine's own stage
// engine_stage_names()[engine_stage], inside `detect`.
struct RunTime {
  RunStage stage;
  int engine_stage = -1;
  double seconds = 0;
  std::string name() const;  // "read", …, "detect.<engine stage>"
};
using RunTimes = std::vector<RunTime>;

// The times as the contact file records them (src/io/contact_file: RunInfo::times).
StageTimes file_stage_times(const RunTimes& times);

}  // namespace cg
