// Redistribution (see distribute.hpp).
#include "distribute.hpp"

#include "transport.hpp"

namespace cg {

HostVector<BodyRecord> distribute_to_owners(const Session& session, Exports<BodyRecord>&& exports) {
  const detail::Comm comm(session);
  const std::vector<std::uint64_t> send_counts = exports.counts();
  const std::vector<std::uint64_t> recv_counts = comm.alltoall_counts(send_counts);
  return comm.alltoallv(std::move(exports.rows), send_counts, recv_counts);
}

}  // namespace cg
