#pragma once
// Typed ids of the stages of one detection, shared by both backends (g++-safe). The public timing
// table (StageTimes: {name, seconds} in stage order) is written from these ids only, so the names and
// their order are stated once, here.
#include <chrono>

#include "engine.hpp"

namespace cg::detail {

// In pipeline order. plan: the engine's (bounds, frame, grid plan; engine.cpp); upload and download:
// CUDA backend only (the host reads and writes in place); skin: the check of candidates kept across
// calls (EngineOptions::skin > 0, when the bodies match the kept list's: the displacement reduction).
enum class EngineStage : int { plan, upload, skin, pack, entries, sort, pairs, order, narrow, download };
inline constexpr int kStageCount = 10;

constexpr const char* name(EngineStage s) {
  switch (s) {
    case EngineStage::plan:
      return "plan";
    case EngineStage::upload:
      return "upload";
    case EngineStage::skin:
      return "skin";
    case EngineStage::pack:
      return "pack";
    case EngineStage::entries:
      return "entries";
    case EngineStage::sort:
      return "sort";
    case EngineStage::pairs:
      return "pairs";
    case EngineStage::order:
      return "order";
    case EngineStage::narrow:
      return "narrow";
    case EngineStage::download:
      return "download";
  }
  return "?";
}

constexpr int index(EngineStage s) { return static_cast<int>(s); }
constexpr EngineStage stage_at(int i) { return static_cast<EngineStage>(i); }

// Wall-clock laps of the host backend: lap(s) appends {name(s), seconds since the previous lap}.
class HostStageTimer {
 public:
  using clock_type = std::chrono::steady_clock;
  explicit HostStageTimer(StageTimes& times) : m_times(times), m_t(clock_type::now()) {}
  void lap(EngineStage s) {
    const auto now = clock_type::now();
    m_times.push_back({name(s), std::chrono::duration<double>(now - m_t).count()});
    m_t = now;
  }

 private:
  StageTimes& m_times;
  clock_type::time_point m_t;
};

}  // namespace cg::detail
