#pragma once
// The times of a distributed run's stages: this rank's, by RunStage (and the engine's stages inside
// detect); times() takes the maximum over ranks of each (collective).
#include <string>
#include <vector>

#include "collectives.hpp"
#include "resident_steps.hpp"  // engine_stage_names
#include "run/run_stage.hpp"
#include "timing.hpp"

namespace cg {

// This rank's stage times; times() gives the maximum over ranks of each, in pipeline order.
class StageClock {
 public:
  void start() { m_t0 = WallClock::now(); }
  void stop(RunStage stage) { m_top[static_cast<std::size_t>(stage)] += seconds_since(m_t0); }
  void add(RunStage stage, double seconds) { m_top[static_cast<std::size_t>(stage)] += seconds; }
  void add_engine(const StageTimes& engine_times) {
    const std::vector<std::string>& names = engine_stage_names();
    for (const StageTime& t : engine_times)
      for (std::size_t k = 0; k < names.size(); ++k)
        if (t.name == names[k]) m_engine[k] = t.seconds;
  }
  // Collective. read, redistribute, halo, detect (then the engine's stages that took time), the
  // contacts' transfer (gather or exchange), merge.
  RunTimes times(const Session& session, RunStage transfer) const {
    std::vector<double> all(m_top.begin(), m_top.end());
    all.insert(all.end(), m_engine.begin(), m_engine.end());
    max_over_ranks(session, all);
    RunTimes out;
    for (RunStage stage : {RunStage::read, RunStage::redistribute, RunStage::halo, RunStage::detect, transfer,
                           RunStage::merge}) {
      out.push_back({stage, -1, all[static_cast<std::size_t>(stage)]});
      if (stage != RunStage::detect) continue;
      for (std::size_t k = 0; k < m_engine.size(); ++k)
        if (all[k_stages + k] > 0) out.push_back({RunStage::detect, static_cast<int>(k), all[k_stages + k]});
    }
    return out;
  }

 private:
  static constexpr std::size_t k_stages = static_cast<std::size_t>(RunStage::csv) + 1;
  WallClock::time_point m_t0 = WallClock::now();
  std::vector<double> m_top = std::vector<double>(k_stages, 0.0);
  std::vector<double> m_engine = std::vector<double>(engine_stage_names().size(), 0.0);
};

}  // namespace cg
