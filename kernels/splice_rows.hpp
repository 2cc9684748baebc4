#pragma once
// A splice of rows (host code, OpenMP): rows `leaving` (strictly ascending) of n rows removed and
// arrival j inserted before old row at[j] (non-decreasing, at most n; arrivals before the rows they
// precede, in their own order). The migration of the resident steps (decomposition/step_bodies:
// merge_step_bodies) and Engine::splice_resident's CPU rows share it; CUDA does the same per row
// (cuda/splice.cuh: splice_kernel). The copies are the runs of rows between the changes, cut into
// pieces that the threads share: the result does not depend on the threads. Large arrays are copied
// with streaming stores (stream_copy.hpp).
#include <algorithm>
#include <cstddef>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "errors.hpp"
#include "stream_copy.hpp"

namespace cg {

struct SpliceRun {
  bool arrival;                 // from the arrivals (else from the old rows)
  std::size_t src, dst, count;  // rows
};

struct SplicePlan {
  std::vector<SpliceRun> pieces;  // runs of at most k_piece rows
  std::size_t size = 0;           // the rows after the splice
  static constexpr std::size_t k_piece = std::size_t(1) << 16;
};

// UsageError naming `what` when `leaving` is not strictly ascending below n or `at` is not
// non-decreasing and at most n.
inline SplicePlan plan_splice(std::size_t n, std::span<const std::size_t> leaving,
                              std::span<const std::size_t> at, const char* what) {
  for (std::size_t k = 0; k < leaving.size(); ++k)
    if (leaving[k] >= n || (k > 0 && !(leaving[k - 1] < leaving[k])))
      throw UsageError(std::string(what) + ": the leaving rows are not ascending rows below " +
                       std::to_string(n));
  for (std::size_t j = 0; j < at.size(); ++j)
    if (at[j] > n || (j > 0 && at[j] < at[j - 1]))
      throw UsageError(std::string(what) + ": the arrivals' places are not ascending places up to " +
                       std::to_string(n));
  std::vector<SpliceRun> runs;
  std::size_t src = 0, dst = 0, li = 0, aj = 0;
  const std::size_t m = at.size();
  while (src < n || aj < m) {
    const std::size_t q = std::min(li < leaving.size() ? leaving[li] : n, aj < m ? at[aj] : n);
    if (q > src) {
      runs.push_back({false, src, dst, q - src});
      dst += q - src;
      src = q;
    }
    const std::size_t a0 = aj;
    while (aj < m && at[aj] == q) ++aj;
    if (aj > a0) {
      runs.push_back({true, a0, dst, aj - a0});
      dst += aj - a0;
    }
    if (li < leaving.size() && leaving[li] == q) {
      ++li;
      src = q + 1;
    }
  }
  SplicePlan plan;
  plan.size = dst;
  for (const SpliceRun& r : runs)
    for (std::size_t o = 0; o < r.count; o += SplicePlan::k_piece)
      plan.pieces.push_back({r.arrival, r.src + o, r.dst + o, std::min(SplicePlan::k_piece, r.count - o)});
  return plan;
}

// One array spliced: `stride` elements a row (from: the old rows, arrivals: theirs, into: plan.size
// rows, distinct from both).
template <class T>
void splice_rows(const SplicePlan& plan, const T* from, const T* arrivals, T* into, std::size_t stride,
                 int threads) {
  static_assert(std::is_trivially_copyable_v<T>);
  const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(plan.pieces.size());
  const bool streamed = stream_copy_wanted(plan.size * stride * sizeof(T));
#pragma omp parallel for num_threads(threads) schedule(dynamic, 4) if (count > 4)
  for (std::ptrdiff_t k = 0; k < count; ++k) {
    const SpliceRun& r = plan.pieces[static_cast<std::size_t>(k)];
    const T* src = (r.arrival ? arrivals : from) + r.src * stride;
    if (streamed)
      stream_copy(into + r.dst * stride, src, r.count * stride * sizeof(T));
    else
      std::copy_n(src, r.count * stride, into + r.dst * stride);
  }
}

}  // namespace cg
