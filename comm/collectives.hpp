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

// Bytes between every pair of ranks: `send` grouped by destination rank, send_bytes[r] of them to
// rank r; returns what every rank sent this one, grouped by source rank (recv_bytes[r] from rank r).
std::vector<std::byte> alltoallv_bytes(const Session& session, const std::vector<std::byte>& send,
                                       const std::vector<std::uint64_t>& send_bytes,
                                       std::vector<std::uint64_t>& recv_bytes);

// values[k] = the maximum of values[k] over the ranks (stage times).
void max_over_ranks(const Session& session, std::vector<double>& values);

}  // namespace cg
