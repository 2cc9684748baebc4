// Halo exchange (see halo_exchange.hpp).
#include "halo_exchange.hpp"

#include "transport.hpp"

namespace cg {

namespace {
template <class T>
Imports<T> exchange_records(const Session& session, const Exports<T>& exports) {
  const detail::Comm comm(session);
  const std::vector<std::uint64_t> send_counts = exports.counts();
  Imports<T> in;
  in.counts = comm.alltoall_counts(send_counts);
  in.rows = comm.exchange(exports.rows, send_counts, in.counts);
  return in;
}
}  // namespace

Imports<BodyRecord> exchange_with_ghost_ranks(const Session& session, const Exports<BodyRecord>& exports) {
  return exchange_records(session, exports);
}

Imports<ShapeRecord> exchange_with_ghost_ranks(const Session& session, const Exports<ShapeRecord>& exports) {
  return exchange_records(session, exports);
}

}  // namespace cg
