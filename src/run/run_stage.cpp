// The names of the run's stages (run_stage.hpp).
#include "run/run_stage.hpp"

#include <iterator>

#include "resident_steps.hpp"  // engine_stage_names

namespace cg {

const char* stage_name(RunStage stage) {
  static constexpr const char* names[] = {"read",     "redistribute", "halo",  "detect", "gather",
                                          "exchange", "merge",        "write", "csv"};
  static_assert(std::size(names) == static_cast<std::size_t>(RunStage::csv) + 1);
  return names[static_cast<std::size_t>(stage)];
}

std::string RunTime::name() const {
  if (engine_stage < 0) return stage_name(stage);
  return std::string(stage_name(stage)) + "." + engine_stage_names()[static_cast<std::size_t>(engine_stage)];
}

StageTimes file_stage_times(const RunTimes& times) {
  StageTimes out;
  for (const RunTime& t : times) out.push_back({t.name(), t.seconds});
  return out;
}

}  // namespace cg
