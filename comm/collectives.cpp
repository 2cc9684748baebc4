// Small collectives over a Session (see collectives.hpp).
#include "collectives.hpp"

#include <algorithm>

#include "transport.hpp"

namespace cg {
namespace {

// Bounds of one rank as exchanged (count 0: the rank read no body and is skipped).
struct BoundsRecord {
  Vec3<double> lo, hi;
  double r_max, r_min;
  std::uint64_t count;
  double r_sum[3];  // radius moments (the tuned cell size)
};
static_assert(std::is_trivially_copyable_v<BoundsRecord>);

}  // namespace

Bounds allgather_bounds(const Session& session, const Bounds& mine) {
  const BoundsRecord record{mine.lo,    mine.hi,    mine.r_max,
                            mine.r_min, mine.count, {mine.r_sum[0], mine.r_sum[1], mine.r_sum[2]}};
  Bounds global;
  bool any = false;
  for (const BoundsRecord& r : detail::Comm(session).allgather(record)) {
    if (r.count == 0) continue;
    Bounds b;
    b.lo = r.lo;
    b.hi = r.hi;
    b.r_max = r.r_max;
    b.r_min = r.r_min;
    b.count = r.count;
    for (int k = 0; k < 3; ++k) b.r_sum[k] = r.r_sum[k];
    if (any) {
      global.merge(b);
    } else {
      global = b;
      any = true;
    }
  }
  return global;
}

std::vector<double> allgather_values(const Session& session, const std::vector<double>& mine) {
  return detail::Comm(session).allgatherv(mine);
}

std::vector<std::uint64_t> allgather_counts(const Session& session, std::uint64_t mine) {
  return detail::Comm(session).allgather<std::uint64_t>(mine);
}

std::vector<std::uint64_t> alltoall_counts(const Session& session,
                                           const std::vector<std::uint64_t>& send_counts) {
  return detail::Comm(session).alltoall_counts(send_counts);
}

void alltoallv_records(const Session& session, std::size_t record_bytes, const void* send,
                       const std::vector<std::uint64_t>& send_counts, void* recv,
                       const std::vector<std::uint64_t>& recv_counts) {
  detail::Comm(session).exchange_rows_into(static_cast<const std::byte*>(send), static_cast<std::byte*>(recv),
                                           record_bytes, send_counts, recv_counts);
}

void max_over_ranks(const Session& session, std::vector<double>& values) {
  detail::Comm(session).allreduce_max(values);
}

}  // namespace cg
