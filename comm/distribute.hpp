#pragma once
// Redistribution: every body to its owner. g++-safe public header.
#include "engine.hpp"
#include "routing.hpp"
#include "session.hpp"

namespace cg {

// Collective. `exports`: this rank's records grouped by owner (route with to_owner); returns the
// records this rank owns, grouped by source rank (each group in the source's row order). Counts by
// MPI_Alltoall, records by MPI_Alltoallv. One rank: the export rows themselves (moved, no copy).
HostVector<BodyRecord> distribute_to_owners(const Session& session, Exports<BodyRecord>&& exports);
// The shape rows of the same bodies (routed by the same rule: received in the same order).
HostVector<ShapeRecord> distribute_to_owners(const Session& session, Exports<ShapeRecord>&& exports);

}  // namespace cg
