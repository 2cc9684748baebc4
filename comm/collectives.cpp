// Small collectives over a Session (see collectives.hpp).
#include "collectives.hpp"

#include <algorithm>
#include <cstring>

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

// The largest message of alltoallv_records (MPI counts are ints).
constexpr std::uint64_t k_records_max_bytes = std::uint64_t(1) << 30;

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
  const std::size_t p = send_counts.size(), me = static_cast<std::size_t>(session.rank());
  std::vector<std::uint64_t> split(p + 1, 0), at(p + 1, 0);
  for (std::size_t r = 0; r < p; ++r) {
    split[r + 1] = split[r] + send_counts[r];
    at[r + 1] = at[r] + recv_counts[r];
  }
  auto* in = static_cast<unsigned char*>(recv);
  const auto* out = static_cast<const unsigned char*>(send);
  if (send_counts[me] > 0)
    std::memcpy(in + at[me] * record_bytes, out + split[me] * record_bytes, send_counts[me] * record_bytes);
  detail::Comm::RowField field;
  field.send = out;
  field.row_bytes = record_bytes;
  field.into.resize(p);
  for (std::size_t r = 0; r < p; ++r) field.into[r] = in + at[r] * record_bytes;
  detail::Comm(session).exchange_rows({field}, split, recv_counts, k_records_max_bytes,
                                      detail::k_records_tag);
}

void max_over_ranks(const Session& session, std::vector<double>& values) {
  detail::Comm(session).allreduce_max(values);
}

}  // namespace cg
