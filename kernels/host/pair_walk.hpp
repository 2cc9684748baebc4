#pragma once
// What the pair stages of the grid (pairs.cpp: Le Grand's cells; cell_walk.cpp: the cell list) share:
// the bound their inner loops skip pairs by, and their progress report.
#include <atomic>
#include <cstdint>
#include <functional>
#include <type_traits>

#include "core/narrow.hpp"

namespace cg::detail::host {

// What the inner loop may pass over without the test: the pairs the test itself rejects by the same
// arithmetic. SpheresTouch and mixed's Fp64Touch reject d² > s² (s = ra + rb) and d² > (s + 2m)²
// (broad_says: apart) respectively, computed here exactly as they compute it (dx = a.x − b.x, …;
// (dx² + dy²) + dz²; the same roundings, no contraction), so a pair is skipped only where the test
// says no; a skipped pair still counts as tested. Every other test (CellRule, CentreCut) sees every
// pair the cell rule assigns.
template <class Test, class Real>
struct NearBound {
  bool all = true;  // no bound: every pair is near
  Real margin2 = 0;
  explicit NearBound(const Test& test) {
    if constexpr (std::is_same_v<Test, SpheresTouch>) {
      all = false;
    } else if constexpr (std::is_same_v<Test, Fp64Touch> && std::is_same_v<Real, float>) {
      all = !(test.margin > 0.0f);  // broad_says is unsure of every pair without a margin
      margin2 = 2.0f * test.margin;
    }
  }
};

// The pair stage's progress (PairLimits::on_progress): each thread adds its tests every kStep of them;
// whichever thread gets the flag reports the sum, so the callback runs on one thread at a time.
class ProgressShare {
 public:
  static constexpr std::uint64_t kStep = std::uint64_t(1) << 24;
  explicit ProgressShare(const std::function<void(std::uint64_t, bool)>* report) : m_report(report) {}
  bool on() const { return m_report != nullptr; }
  void add(std::uint64_t tests) {
    const std::uint64_t done = m_done.fetch_add(tests, std::memory_order_relaxed) + tests;
    if (m_busy.test_and_set(std::memory_order_acquire)) return;
    (*m_report)(done, false);
    m_busy.clear(std::memory_order_release);
  }
  void finish() {
    if (on()) (*m_report)(m_done.load(), true);
  }

 private:
  const std::function<void(std::uint64_t, bool)>* m_report;
  std::atomic<std::uint64_t> m_done{0};
  std::atomic_flag m_busy = ATOMIC_FLAG_INIT;
};

}  // namespace cg::detail::host
