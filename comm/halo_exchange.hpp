#pragma once
// Halo exchange: the ghosts of every rank. g++-safe public header.
#include <cstdint>
#include <vector>

#include "engine.hpp"
#include "routing.hpp"
#include "session.hpp"

namespace cg {

// What a rank receives, grouped by source rank: rows from rank r are the counts[r] after those of
// the ranks before it.
template <class T>
struct Imports {
  HostVector<T> rows;
  std::vector<std::uint64_t> counts;
};

// Collective. `exports`: this rank's owned records grouped by destination (route with
// to_ghost_ranks); returns this rank's ghosts. Counts by MPI_Alltoall, then every Irecv posted,
// every Isend, one Waitall (only ranks with something to send or receive take part).
Imports<BodyRecord> exchange_with_ghost_ranks(const Session& session, const Exports<BodyRecord>& exports);
// The shape rows of the same ghosts (routed by the same rule: received in the same order).
Imports<ShapeRecord> exchange_with_ghost_ranks(const Session& session, const Exports<ShapeRecord>& exports);

}  // namespace cg
