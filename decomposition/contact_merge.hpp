#pragma once
// Merge of the sorted contact runs of the ranks into one sorted, duplicate-free list (rank 0 of an MPI
// run). Pure host code, no MPI.
//
// A k-way merge with a binary heap keyed by (id_a, id_b, run): O(K log P) for K contacts of P runs,
// not a full sort. Ties between runs are taken in run (rank) order, so the result is deterministic.
// Rows whose (id_a, id_b) equals the previous output row are dropped and counted: with ownership of
// pairs (the owner of the smaller id reports) there are none; the count is the safety net's report.
#include <cstdint>
#include <functional>
#include <queue>
#include <span>
#include <string>
#include <tuple>
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
  out.id_a.push_back(in.id_a[k]);
  out.id_b.push_back(in.id_b[k]);
  out.position_on_a.push_back(in.position_on_a[k]);
  out.position_on_b.push_back(in.position_on_b[k]);
  out.normal_on_b.push_back(in.normal_on_b[k]);
  out.distance.push_back(in.distance[k]);
  if (out.full) {
    out.local_point_a.push_back(in.local_point_a[k]);
    out.local_point_b.push_back(in.local_point_b[k]);
    out.lateral_friction_dir1.push_back(in.lateral_friction_dir1[k]);
    out.lateral_friction_dir2.push_back(in.lateral_friction_dir2[k]);
  }
}

template <class Real>
void check_contact_run(const Contacts<Real>& run, std::size_t index, bool full) {
  const std::size_t n = run.id_a.size();
  const std::string name = "contact run " + std::to_string(index);
  bool sizes = run.id_b.size() == n && run.position_on_a.size() == n && run.position_on_b.size() == n &&
               run.normal_on_b.size() == n && run.distance.size() == n;
  if (full) {
    sizes = sizes && run.full && run.local_point_a.size() == n && run.local_point_b.size() == n &&
            run.lateral_friction_dir1.size() == n && run.lateral_friction_dir2.size() == n;
  }
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
  out.id_a.reserve(total);
  out.id_b.reserve(total);
  out.position_on_a.reserve(total);
  out.position_on_b.reserve(total);
  out.normal_on_b.reserve(total);
  out.distance.reserve(total);
  if (full) {
    out.local_point_a.reserve(total);
    out.local_point_b.reserve(total);
    out.lateral_friction_dir1.reserve(total);
    out.lateral_friction_dir2.reserve(total);
  }

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

}  // namespace cg
