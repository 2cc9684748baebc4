#pragma once
// What the pair stages of the grid (pairs.cpp: Le Grand's cells; cell_walk.cpp: the cell list) share:
// the bound their inner loops skip pairs by, their progress report, and their chunked collection.
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <functional>
#include <type_traits>
#include <vector>

#include "core/narrow.hpp"
#include "host/stages.hpp"

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

// The pairs of places [0, n) (entries or listed bodies) collected count → scan → fill at the
// granularity of fixed chunks: each chunk walks its places once, in steps of k_step with
// walk_step(begin, end, emit) → its tests (emit(a, b) appends a pair), the chunk sizes are scanned,
// the chunks copied in order into out.ab. The chunking depends only on n, so the pair array is the
// same for any thread count. A thread appends its chunks' pairs to its own buffer, kept for the
// thread's later calls: the chunks' growing arrays would be fresh heap pages every call (the kernel
// zeroing each on first touch) and copies as they grow. A buffer above k_kept_bytes is freed after
// the copy (the memory a scene of many contacts leaves behind). Returns the tests.
template <class WalkStep>
std::uint64_t collect_in_chunks(std::size_t n, int nt, CandidatePairs& out, ProgressShare& progress,
                                const WalkStep& walk_step) {
  constexpr std::size_t k_kept_bytes = std::size_t(32) << 20;
  const int id_bits = out.id_bits;
  const std::size_t n_chunks = std::max<std::size_t>(1, std::min<std::size_t>(256, n / 16384));
  struct ChunkRun {
    std::vector<std::uint64_t>* buffer = nullptr;
    std::size_t begin = 0, size = 0;
  };
  std::vector<ChunkRun> chunk_run(n_chunks);
  std::uint64_t tests_total = 0;
#pragma omp parallel num_threads(nt) reduction(+ : tests_total) if (n_chunks > 1)
  {
    static thread_local std::vector<std::uint64_t> mine;
    mine.clear();
    auto emit = [&](std::uint32_t a, std::uint32_t b) { mine.push_back((std::uint64_t(a) << id_bits) | b); };
#pragma omp for schedule(dynamic, 1)
    for (std::size_t c = 0; c < n_chunks; ++c) {
      const std::size_t begin = mine.size();
      std::uint64_t unreported = 0;
      constexpr std::size_t k_step = 4096;  // progress: reported after each step of places
      for (std::size_t i = n * c / n_chunks, end = n * (c + 1) / n_chunks; i < end; i += k_step) {
        const std::uint64_t tests = walk_step(i, std::min(end, i + k_step), emit);
        tests_total += tests;
        unreported += tests;
        if (progress.on() && unreported >= ProgressShare::kStep) {
          progress.add(unreported);
          unreported = 0;
        }
      }
      if (progress.on() && unreported > 0) progress.add(unreported);
      chunk_run[c] = {&mine, begin, mine.size() - begin};
    }
  }
  progress.finish();
  std::vector<std::uint64_t> chunk_size(n_chunks), chunk_offset;
  for (std::size_t c = 0; c < n_chunks; ++c) chunk_size[c] = chunk_run[c].size;
  out.ab.resize(exclusive_scan_into(chunk_size, chunk_offset));
#pragma omp parallel for num_threads(nt) schedule(static) if (n_chunks > 1)
  for (std::size_t c = 0; c < n_chunks; ++c) {
    const std::uint64_t* from = chunk_run[c].buffer->data() + chunk_run[c].begin;
    std::copy(from, from + chunk_run[c].size, out.ab.begin() + std::ptrdiff_t(chunk_offset[c]));
  }
  for (const ChunkRun& run : chunk_run)
    if (run.buffer->capacity() * sizeof(std::uint64_t) > k_kept_bytes)
      std::vector<std::uint64_t>().swap(*run.buffer);
  return tests_total;
}

}  // namespace cg::detail::host
