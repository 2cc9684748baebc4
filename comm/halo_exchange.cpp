// Halo exchange (see halo_exchange.hpp).
#include "halo_exchange.hpp"

#include "transport.hpp"

namespace cg {

Imports<BodyRecord> exchange_ghosts(const Session& session, const Exports<BodyRecord>& exports) {
  const detail::Comm comm(session);
  const std::vector<std::uint64_t> send_counts = exports.counts();
  Imports<BodyRecord> in;
  in.counts = comm.alltoall_counts(send_counts);
  in.rows = comm.exchange(exports.rows, send_counts, in.counts);
  return in;
}

}  // namespace cg
