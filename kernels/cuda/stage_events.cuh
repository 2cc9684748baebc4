#pragma once
// The CUDA backend's stage timer: CUDA events on the stream, one per typed stage (stage.hpp). A stage's
// time is the span from the previous recorded stage's event to its own. The type-pass path replaces
// the entries, sort and pairs times by the sums over its passes (set_time), the pairs time plus the
// tail from the last pass to the pairs event (add_tail).
#include <algorithm>
#include <chrono>
#include <cstdio>

#include "cuda/device_buffer.cuh"
#include "stage.hpp"

namespace cg::detail {

class StageEvents {
 public:
  static constexpr int kPassEvents = 1 + 3 * 8;  // type passes: start, then per pass fill/sort/count ends

  StageEvents() = default;
  // Creates the events on the current device (called once the backend has set its device).
  void create() {
    for (auto& e : m_events) CG_CUDA_CHECK(cudaEventCreate(&e));
    for (auto& e : m_pass) CG_CUDA_CHECK(cudaEventCreate(&e));
    for (auto& e : m_split) CG_CUDA_CHECK(cudaEventCreate(&e));
  }
  ~StageEvents() {
    for (auto& e : m_events)
      if (e) cudaEventDestroy(e);
    for (auto& e : m_pass)
      if (e) cudaEventDestroy(e);
    for (auto& e : m_split)
      if (e) cudaEventDestroy(e);
  }
  StageEvents(const StageEvents&) = delete;
  StageEvents& operator=(const StageEvents&) = delete;

  // The start of a call (before the first stage).
  void start(cudaStream_t st) {
    std::fill(std::begin(m_recorded), std::end(m_recorded), false);
    std::fill(std::begin(m_override), std::end(m_override), false);
    m_tail = false;
    m_split_marks = 0;
    m_host_start = std::chrono::steady_clock::now();
    CG_CUDA_CHECK(cudaEventRecord(m_events[0], st));
  }
  cudaEvent_t start_event() const { return m_events[0]; }
  // The end of stage s.
  void mark(EngineStage s, cudaStream_t st) {
    CG_CUDA_CHECK(cudaEventRecord(m_events[index(s) + 1], st));
    m_recorded[index(s)] = true;
    m_host_mark[index(s)] = std::chrono::steady_clock::now();
  }
  cudaEvent_t end_event(EngineStage s) const { return m_events[index(s) + 1]; }
  cudaEvent_t pass_event(int i) const { return m_pass[i]; }
  // Stage s takes `ms` instead of its event span (type passes).
  void set_time(EngineStage s, double ms) {
    m_override[index(s)] = true;
    m_override_ms[index(s)] = ms;
  }
  // Stage s's set time also gets the span from the last pass event to its end event.
  void add_tail(EngineStage s) {
    m_tail = true;
    m_tail_stage = s;
  }

  // The narrow stage's split (scenes with ellipsoids): marks 0, 1, 2, 3 at its start, after the
  // triage pass, after the settle pass, after the hard pass (each with its selection).
  void mark_narrow_split(int i, cudaStream_t st) {
    CG_CUDA_CHECK(cudaEventRecord(m_split[i], st));
    m_split_marks = i + 1;
  }
  // Seconds of the triage, settle and hard passes (EngineStats::narrow_triage_s, …); 0 when the call
  // did not mark them. After the stream's synchronisation.
  void narrow_split(double& triage, double& settle, double& hard) const {
    triage = settle = hard = 0;
    if (m_split_marks < 4) return;
    float t = 0, s = 0, h = 0;
    CG_CUDA_CHECK(cudaEventElapsedTime(&t, m_split[0], m_split[1]));
    CG_CUDA_CHECK(cudaEventElapsedTime(&s, m_split[1], m_split[2]));
    CG_CUDA_CHECK(cudaEventElapsedTime(&h, m_split[2], m_split[3]));
    triage = t * 1e-3;
    settle = s * 1e-3;
    hard = h * 1e-3;
  }

  // Appends the recorded stages to `times` (all events complete: the stream was synchronised).
  // download: the larger of its span and `download_overlap_s`, plus `download_extra_s` (host work).
  void collect(StageTimes& times, double download_overlap_s, double download_extra_s) const {
    cudaEvent_t prev = m_events[0];
    for (int i = 0; i < kStageCount; ++i) {
      if (!m_recorded[i]) continue;
      float ms = 0;
      CG_CUDA_CHECK(cudaEventElapsedTime(&ms, prev, m_events[i + 1]));
      double sec = ms * 1e-3;
      if (m_override[i]) {
        double o = m_override_ms[i];
        if (m_tail && i == index(m_tail_stage)) {
          float tail = 0;
          CG_CUDA_CHECK(cudaEventElapsedTime(&tail, m_pass[kPassEvents - 1], m_events[i + 1]));
          o += tail;
        }
        sec = o * 1e-3;
      }
      if (i == index(EngineStage::download)) sec = std::max(sec, download_overlap_s) + download_extra_s;
      times.push_back({name(stage_at(i)), sec});
      prev = m_events[i + 1];
    }
  }

  // CONTACTGRID_CUDA_TRACE=1: one line on stderr a call, the host's clock (ms after `entry`, the run's
  // start) when each stage was queued and when the call ended, beside the stages' event times: what the
  // host waits on, which the events alone do not show. After collect.
  void trace(std::chrono::steady_clock::time_point entry, const StageTimes& times) const {
    using ms = std::chrono::duration<double, std::milli>;
    const auto end = std::chrono::steady_clock::now();
    std::fprintf(stderr, "cuda trace: start %.3f", ms(m_host_start - entry).count());
    for (int i = 0; i < kStageCount; ++i)
      if (m_recorded[i])
        std::fprintf(stderr, ", %s queued %.3f", name(stage_at(i)), ms(m_host_mark[i] - entry).count());
    std::fprintf(stderr, ", end %.3f | events:", ms(end - entry).count());
    for (const auto& t : times) std::fprintf(stderr, " %s %.3f", t.name.c_str(), t.seconds * 1e3);
    std::fprintf(stderr, "\n");
  }

 private:
  std::chrono::steady_clock::time_point m_host_start{}, m_host_mark[kStageCount] = {};
  cudaEvent_t m_events[kStageCount + 1] = {};
  cudaEvent_t m_pass[kPassEvents] = {};
  cudaEvent_t m_split[4] = {};
  int m_split_marks = 0;
  bool m_recorded[kStageCount] = {};
  bool m_override[kStageCount] = {};
  double m_override_ms[kStageCount] = {};
  bool m_tail = false;
  EngineStage m_tail_stage = EngineStage::pairs;
};

}  // namespace cg::detail
