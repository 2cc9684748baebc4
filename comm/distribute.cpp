// Redistribution (see distribute.hpp).
#include "distribute.hpp"

#include "transport.hpp"

namespace cg {

namespace {
template <class T>
HostVector<T> distribute_records(const Session& session, Exports<T>&& exports) {
  const detail::Comm comm(session);
  const std::vector<std::uint64_t> send_counts = exports.counts();
  const std::vector<std::uint64_t> recv_counts = comm.alltoall_counts(send_counts);
  return comm.alltoallv(std::move(exports.rows), send_counts, recv_counts);
}
}  // namespace

HostVector<BodyRecord> distribute_to_owners(const Session& session, Exports<BodyRecord>&& exports) {
  return distribute_records(session, std::move(exports));
}

HostVector<ShapeRecord> distribute_to_owners(const Session& session, Exports<ShapeRecord>&& exports) {
  return distribute_records(session, std::move(exports));
}

}  // namespace cg
