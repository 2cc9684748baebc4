#pragma once
// Small collectives of the distributed run over a Session (every rank calls them, in the same order).
// g++-safe public header; in laptop mode each is the one-rank identity.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "engine.hpp"
#include "session.hpp"

namespace cg {

// The global bounds: every rank's `mine` all-gathered and folded with Bounds::merge in rank order;
// ranks with mine.count == 0 (no body) are skipped. Every rank gets the same bits.
Bounds allgather_bounds(const Session& session, const Bounds& mine);

// Every rank's values, concatenated in rank order.
std::vector<double> allgather_values(const Session& session, const std::vector<double>& mine);

// Every rank's count, in rank order.
std::vector<std::uint64_t> allgather_counts(const Session& session, std::uint64_t mine);

// Records of `record_bytes` each between every pair of ranks, without staging copies: `send` grouped
// by destination rank (send_counts[r] records to rank r), `recv` grouped by source rank
// (recv_counts[r] from rank r: alltoall_counts). Point to point, only between ranks with records,
// one message of records a pair (fewer than 2^31 records); this rank's own records are copied.
std::vector<std::uint64_t> alltoall_counts(const Session& session,
                                           const std::vector<std::uint64_t>& send_counts);
void alltoallv_records(const Session& session, std::size_t record_bytes, const void* send,
                       const std::vector<std::uint64_t>& send_counts, void* recv,
                       const std::vector<std::uint64_t>& recv_counts);

// values[k] = the maximum of values[k] over the ranks (stage times).
void max_over_ranks(const Session& session, std::vector<double>& values);

}  // namespace cg
