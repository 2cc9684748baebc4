#pragma once
// Contact identity across steps, host side (g++-safe public header, part of engine.hpp): the previous
// step's pair keys and ages (ContactHistory) and the step that gives a new step's rows their history
// fields and makes them the previous step (core/history.hpp states the rule). The engine keeps one
// ContactHistory per engine (EngineOptions::history); a caller that merges several engines' rows
// (an MPI step loop) keeps its own and steps it over the merged rows.
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "contacts.hpp"
#include "core/history.hpp"

namespace cg {

// The rows of the previous step, in their order: pair keys (ascending) and ages.
struct ContactHistory {
  std::vector<PairKey> keys;
  std::vector<std::int64_t> age;
  std::size_t size() const { return keys.size(); }
  void clear() {
    keys.clear();
    age.clear();
  }
};

// Fills c.age and c.previous_row of every row of `c` against `previous` (c.history becomes true), then
// makes `previous` the history of c. Keys: the rows' ids, or with `global_ids` non-empty the global
// ids of the rows' ids (local indices into it). Precondition: c's keys ascending (Contacts are
// sorted by (id_a, id_b); global_ids ascending). `threads` OpenMP threads (0: all).
template <class Real>
void step_history(Contacts<Real>& c, ContactHistory& previous, std::span<const std::int64_t> global_ids = {},
                  int threads = 0);

}  // namespace cg
