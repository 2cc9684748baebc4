#pragma once
// Merge of the sorted contact runs of the ranks into one sorted, duplicate-free list (rank 0 of an MPI
// run). Pure host code, no MPI.
//
// A k-way merge with a binary heap keyed by (id_a, id_b, run): O(K log P) for K contacts of P runs,
// not a full sort. Ties between runs are taken in run (rank) order, so the result is deterministic.
// Rows whose (id_a, id_b) equals the previous output row are dropped and counted: with ownership of
// pairs (the owner of the smaller id reports) there are none; the count is the safety net's report.
// merge_contact_runs_into (below) computes the same rows in parallel, from views of the runs into a
// presized result: the MPI run uses it; merge_contact_runs is its sequential reference.
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <functional>
#include <queue>
#include <span>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "engine.hpp"

namespace cg {

template <class Real>
struct MergedContacts {
  Contacts<Real> contacts;
  std::uint64_t duplicates_removed = 0;
};

namespace detail {

template <class Real>
void append_contact_row(Contacts<Real>& out, const Contacts<Real>& in, std::size_t k) {
  zip_contact_fields(out, in, out.full, [k](auto, auto& to, const auto& from) { to.push_back(from[k]); });
}

template <class Real>
void check_contact_run(const Contacts<Real>& run, std::size_t index, bool full) {
  const std::size_t n = run.id_a.size();
  const std::string name = "contact run " + std::to_string(index);
  const bool sizes = run.consistent() && (!full || run.full);
  if (!sizes) throw Error(name + ": fields of different lengths (or optional fields missing)");
  for (std::size_t k = 1; k < n; ++k) {
    if (std::tie(run.id_a[k - 1], run.id_b[k - 1]) > std::tie(run.id_a[k], run.id_b[k])) {
      throw Error(name + ": not sorted by (id_a, id_b) at row " + std::to_string(k));
    }
  }
}

}  // namespace detail

// Precondition: every run sorted by (id_a, id_b) with all fields of equal length, and carrying the
// optional fields when `full` (Error naming the run otherwise: an internal error).
template <class Real>
MergedContacts<Real> merge_contact_runs(std::span<const Contacts<Real>> runs, bool full) {
  MergedContacts<Real> result;
  Contacts<Real>& out = result.contacts;
  out.full = full;
  std::size_t total = 0;
  for (std::size_t r = 0; r < runs.size(); ++r) {
    detail::check_contact_run(runs[r], r, full);
    total += runs[r].size();
  }
  out.reserve(total, full);

  using Head = std::tuple<std::int64_t, std::int64_t, std::size_t>;  // (id_a, id_b, run)
  std::priority_queue<Head, std::vector<Head>, std::greater<Head>> heap;
  std::vector<std::size_t> next(runs.size(), 0);
  for (std::size_t r = 0; r < runs.size(); ++r) {
    if (runs[r].size() > 0) heap.emplace(runs[r].id_a[0], runs[r].id_b[0], r);
  }
  while (!heap.empty()) {
    auto [a, b, r] = heap.top();
    heap.pop();
    const std::size_t k = next[r]++;
    const std::size_t n = out.size();
    if (n > 0 && out.id_a[n - 1] == a && out.id_b[n - 1] == b) {
      ++result.duplicates_removed;
    } else {
      detail::append_contact_row(out, runs[r], k);
    }
    if (next[r] < runs[r].size()) heap.emplace(runs[r].id_a[next[r]], runs[r].id_b[next[r]], r);
  }
  return result;
}

// ---- the same merge, in parallel, from views, into a presized result -----------------------------

// One run's fields, read-only, in place: a Contacts (contact_run_view) or receive buffers.
template <class Real>
struct ContactRunView : ContactColumns<Real, ConstPtr> {
  std::size_t n = 0;
};

// Rows [first, first + count) of `c` (count npos: to the end) as a run; the optional fields when `full`.
template <class Real>
ContactRunView<Real> contact_run_view(const Contacts<Real>& c, bool full, std::size_t first = 0,
                                      std::size_t count = std::size_t(-1)) {
  ContactRunView<Real> v;
  v.n = count == std::size_t(-1) ? c.size() - first : count;
  zip_contact_fields(v, c, full,
                     [first](auto, auto*& ptr, const auto& column) { ptr = column.data() + first; });
  return v;
}

// The rows of merge_contact_runs (same order, same duplicates dropped and counted; returned), written
// straight into `out`, whose fields must be sized to the total of the runs (they are shrunk by the
// duplicates). The key range is cut into `parts` at keys of the largest run, every run cut at the same
// keys by binary search — so equal keys stay in one part and the parts concatenate in order — and the
// parts are merged independently (by `threads` OpenMP threads where compiled with OpenMP). The result
// does not depend on `parts` or `threads`. Runs must be sorted by (id_a, id_b): Error naming the run
// and row otherwise (as merge_contact_runs).
template <class Real>
std::uint64_t merge_contact_runs_into(const std::vector<ContactRunView<Real>>& runs, Contacts<Real>& out,
                                      bool full, int parts_wanted, int threads) {
  using Key = std::pair<std::int64_t, std::int64_t>;
  (void)threads;  // used by the OpenMP pragmas only
  const std::size_t p = runs.size();
  auto key = [&](std::size_t r, std::size_t k) { return Key{runs[r].id_a[k], runs[r].id_b[k]}; };
  for (std::size_t r = 0; r < p; ++r) {
    const std::size_t n = runs[r].n;
    std::size_t bad = n;  // first row k >= 1 out of order
#pragma omp parallel for num_threads(threads) reduction(min    \
                                                        : bad) \
    schedule(static) if (n > (std::size_t(1) << 15))
    for (std::size_t k = 1; k < n; ++k) {
      if (k < bad && key(r, k - 1) > key(r, k)) bad = k;
    }
    if (bad < n) {
      throw Error("contact run " + std::to_string(r) + ": not sorted by (id_a, id_b) at row " +
                  std::to_string(bad));
    }
  }
  std::size_t total = 0, largest = 0;
  for (std::size_t r = 0; r < p; ++r) {
    total += runs[r].n;
    if (runs[r].n > runs[largest].n) largest = r;
  }
  if (out.size() != total || out.distance.size() != total || (full && out.local_point_a.size() != total))
    throw Error("merge_contact_runs_into: the result is not sized to the runs");
  const std::size_t parts = p == 0 ? 1 : static_cast<std::size_t>(std::max(1, parts_wanted));
  // cut[j * p + r]: first row of run r in part j (j = 0 … parts)
  std::vector<std::size_t> cut((parts + 1) * p, 0);
  for (std::size_t r = 0; r < p; ++r) cut[parts * p + r] = runs[r].n;
  for (std::size_t j = 1; j < parts; ++j) {
    if (runs[largest].n == 0) break;
    const Key split = key(largest, runs[largest].n * j / parts);
    for (std::size_t r = 0; r < p; ++r) {
      std::size_t lo = 0, hi = runs[r].n;  // lower_bound(split)
      while (lo < hi) {
        const std::size_t mid = (lo + hi) / 2;
        if (key(r, mid) < split)
          lo = mid + 1;
        else
          hi = mid;
      }
      cut[j * p + r] = lo;
    }
  }
  std::vector<std::size_t> start(parts + 1, 0), written(parts, 0);
  for (std::size_t j = 0; j <= parts; ++j)
    for (std::size_t r = 0; r < p; ++r) start[j] += cut[j * p + r];
  const ContactColumns<Real, Ptr> dst = columns_of(out);
  std::int64_t* da = dst.id_a;
  std::int64_t* db = dst.id_b;
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1) if (parts > 1)
  for (std::size_t j = 0; j < parts; ++j) {
    std::vector<std::size_t> next(p), end(p);
    for (std::size_t r = 0; r < p; ++r) {
      next[r] = cut[j * p + r];
      end[r] = cut[(j + 1) * p + r];
    }
    std::size_t w = start[j];
    auto take = [&](std::size_t r) {  // the head of run r to the output (unless a duplicate)
      const std::size_t k = next[r]++;
      const ContactRunView<Real>& in = runs[r];
      const std::int64_t a = in.id_a[k], b = in.id_b[k];
      if (w > start[j] && da[w - 1] == a && db[w - 1] == b) return;
      zip_contact_fields(dst, in, full, [w, k](auto, auto* to, const auto* from) { to[w] = from[k]; });
      ++w;
    };
    if (p <= 8) {
      // few runs: the smallest head by a linear scan (ties: the lowest run, as the heap's (key, run))
      for (;;) {
        std::size_t best = p;
        for (std::size_t r = 0; r < p; ++r) {
          if (next[r] < end[r] && (best == p || key(r, next[r]) < key(best, next[best]))) best = r;
        }
        if (best == p) break;
        take(best);
      }
    } else {
      using Head = std::tuple<std::int64_t, std::int64_t, std::size_t>;  // (id_a, id_b, run)
      std::priority_queue<Head, std::vector<Head>, std::greater<Head>> heap;
      for (std::size_t r = 0; r < p; ++r) {
        if (next[r] < end[r]) heap.emplace(runs[r].id_a[next[r]], runs[r].id_b[next[r]], r);
      }
      while (!heap.empty()) {
        const std::size_t r = std::get<2>(heap.top());
        heap.pop();
        take(r);
        if (next[r] < end[r]) heap.emplace(runs[r].id_a[next[r]], runs[r].id_b[next[r]], r);
      }
    }
    written[j] = w - start[j];
  }
  // Duplicates (expected none) leave gaps at the ends of parts: close them, in order.
  std::size_t w = 0;
  for (std::size_t j = 0; j < parts; ++j) {
    if (w != start[j] && written[j] > 0) {
      for_each_contact_field(dst, full, [&](auto, auto* column) {
        std::memmove(column + w, column + start[j], written[j] * sizeof(*column));
      });
    }
    w += written[j];
  }
  if (w != total) out.resize(w, full);
  return total - w;
}

}  // namespace cg
