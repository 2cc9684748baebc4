#pragma once
// The times of a distributed run's stages: this rank's, by Stage (and the engine's stages inside
// detect); times() takes the maximum over ranks of each (collective).
#include <chrono>
#include <string>
#include <vector>

#include "collectives.hpp"
#include "run/pipeline.hpp"

namespace cg {

using clock_type = std::chrono::steady_clock;
inline double seconds_since(clock_type::time_point t) {
  return std::chrono::duration<double>(clock_type::now() - t).count();
}

// This rank's stage times; times() gives the maximum over ranks of each, in pipeline order.
class StageClock {
 public:
  void start() { m_t0 = clock_type::now(); }
  void stop(Stage stage) { m_top[static_cast<std::size_t>(stage)] += seconds_since(m_t0); }
  void add(Stage stage, double seconds) { m_top[static_cast<std::size_t>(stage)] += seconds; }
  void add_engine(const StageTimes& engine_times) {
    const std::vector<std::string>& names = engine_stage_names();
    for (const StageTime& t : engine_times)
      for (std::size_t k = 0; k < names.size(); ++k)
        if (t.name == names[k]) m_engine[k] = t.seconds;
  }
  // Collective. read, redistribute, halo, detect (then the engine's stages that took time), the
  // contacts' transfer (gather or exchange), merge.
  RunTimes times(const Session& session, Stage transfer) const {
    std::vector<double> all(m_top.begin(), m_top.end());
    all.insert(all.end(), m_engine.begin(), m_engine.end());
    max_over_ranks(session, all);
    RunTimes out;
    for (Stage stage :
         {Stage::read, Stage::redistribute, Stage::halo, Stage::detect, transfer, Stage::merge}) {
      out.push_back({stage, -1, all[static_cast<std::size_t>(stage)]});
      if (stage != Stage::detect) continue;
      for (std::size_t k = 0; k < m_engine.size(); ++k)
        if (all[k_stages + k] > 0) out.push_back({Stage::detect, static_cast<int>(k), all[k_stages + k]});
    }
    return out;
  }

 private:
  static constexpr std::size_t k_stages = static_cast<std::size_t>(Stage::csv) + 1;
  clock_type::time_point m_t0 = clock_type::now();
  std::vector<double> m_top = std::vector<double>(k_stages, 0.0);
  std::vector<double> m_engine = std::vector<double>(engine_stage_names().size(), 0.0);
};

}  // namespace cg
