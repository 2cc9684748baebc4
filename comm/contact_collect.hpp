#pragma once
// Contacts collected from the ranks, in one of two shapes. g++-safe public header.
//
//  gather_contacts (rank 0 holds all):
//   gather        counts, then each field to rank 0 point to point, straight into one receive array
//                 per rank and field (rank 0's own run stays in place), in messages of at most
//                 max_message_bytes (so no count exceeds 2^31).
//   merge         rank 0: k-way merge of the P sorted runs by (id_a, id_b), exact duplicates removed
//                 and counted (expected 0) — the result of decomposition/merge_contact_runs, computed
//                 in parallel over key ranges straight into the result.
//  exchange_contacts (no rank holds them all):
//   exchange      rank r is responsible for the output rows with id_a in [N·r/P, N·(r+1)/P) (the
//                 rows it read: known before detection). A rank's contacts are sorted by
//                 (id_a, id_b), so its part for each destination is one sub-range (binary search):
//                 counts by Alltoall, then every field's slice sent straight from the arrays (every
//                 Irecv posted, every Isend, one Waitall; messages of at most max_message_bytes), into
//                 one receive array per source and field (the rank's own part stays in place).
//   merge         every rank: k-way merge of its P received runs, duplicates removed (summed over
//                 ranks: expected 0); an all-gather of the merged counts gives each rank its first
//                 output row and the total K.
// Both: the input is this rank's contacts sorted by (id_a, id_b) (the engine's output); one rank's
// single run is the result as it is (moved). The merge line (with the duplicate count) goes to
// options.log on rank 0, or, when no log is given, to stderr as a warning if duplicates were removed.
#include <cstdint>
#include <functional>
#include <string>

#include "engine.hpp"
#include "session.hpp"

namespace cg {

struct CollectOptions {
  std::uint64_t max_message_bytes = 1u << 30;  // per-message size (tests make it tiny)
  int threads = 1;                             // the merge's threads
  std::function<void(const std::string&)> log;
};

template <class Real>
struct CollectedContacts {
  // This rank's rows [first_row, first_row + contacts.size()) of the K sorted contacts: every contact
  // with id_a in [id_begin, id_end). gather: all of them on rank 0, none elsewhere.
  Contacts<Real> contacts;
  std::uint64_t first_row = 0;
  std::uint64_t total_contacts = 0;  // K, on every rank
  std::uint64_t id_begin = 0, id_end = 0;
  std::uint64_t duplicates_removed = 0;  // gather: rank 0's; exchange: summed, every rank
  double transfer_seconds = 0;           // this rank's gather or exchange
  double merge_seconds = 0;              // this rank's merge
};

// Collective. `bodies`: the global body count N.
template <class Real>
CollectedContacts<Real> gather_contacts(const Session& session, Contacts<Real>&& local, std::uint64_t bodies,
                                        const CollectOptions& options);
template <class Real>
CollectedContacts<Real> exchange_contacts(const Session& session, Contacts<Real>&& local,
                                          std::uint64_t bodies, const CollectOptions& options);

}  // namespace cg
