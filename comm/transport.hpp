#pragma once
// Internal to comm/ (includes <mpi.h> through mpi_detail.hpp): the point-to-point and collective
// transport of the distributed run over the session's communicator. In laptop mode (no MPI) every
// call is the one-rank identity, so one rank runs the same code path with no neighbours.
// Element types are trivially copyable and sent as bytes (homogeneous nodes).
#include <algorithm>
#include <climits>
#include <cstdint>
#include <cstring>
#include <type_traits>
#include <vector>

#include "engine.hpp"
#include "mpi_detail.hpp"

namespace cg::detail {

constexpr int k_halo_tag = 7301;
constexpr int k_gather_tag = 7400;    // + field index
constexpr int k_exchange_tag = 7500;  // + field index

class Comm {
 public:
  explicit Comm(const Session& session) : m_s(session.impl()) {}
  int rank() const { return m_s.rank; }
  int size() const { return m_s.size; }

  template <class T>
  std::vector<T> allgather(const T& value) const {
    if (!m_s.mpi) return {value};
    std::vector<T> out(static_cast<std::size_t>(m_s.size));
    RecordType type(sizeof(T));
    CG_MPI(MPI_Allgather(&value, 1, type.get(), out.data(), 1, type.get(), m_s.comm));
    return out;
  }

  template <class T>
  std::vector<T> allgatherv(const std::vector<T>& local) const {
    if (!m_s.mpi) return local;
    std::vector<std::uint64_t> n = allgather<std::uint64_t>(local.size());
    std::vector<int> counts(n.size()), displs(n.size());
    std::uint64_t total = 0;
    for (std::size_t r = 0; r < n.size(); ++r) {
      counts[r] = to_mpi_count(n[r], "all-gather count");
      displs[r] = to_mpi_count(total, "all-gather displacement");
      total += n[r];
    }
    std::vector<T> out(total);
    RecordType type(sizeof(T));
    CG_MPI(MPI_Allgatherv(local.data(), counts[static_cast<std::size_t>(m_s.rank)], type.get(), out.data(),
                          counts.data(), displs.data(), type.get(), m_s.comm));
    return out;
  }

  // recv[r] = what rank r sends to this rank.
  std::vector<std::uint64_t> alltoall_counts(const std::vector<std::uint64_t>& send) const {
    if (!m_s.mpi) return send;
    std::vector<std::uint64_t> recv(send.size());
    CG_MPI(MPI_Alltoall(send.data(), 1, MPI_UINT64_T, recv.data(), 1, MPI_UINT64_T, m_s.comm));
    return recv;
  }

  // `send` grouped by destination rank (send_counts), result grouped by source rank. One rank:
  // the send buffer itself (moved, no copy).
  template <class T>
  HostVector<T> alltoallv(HostVector<T>&& send, const std::vector<std::uint64_t>& send_counts,
                          const std::vector<std::uint64_t>& recv_counts) const {
    if (!m_s.mpi || m_s.size == 1) return std::move(send);
    const std::size_t p = send_counts.size();
    std::vector<int> sc(p), sd(p), rc(p), rd(p);
    std::uint64_t st = 0, rt = 0;
    for (std::size_t r = 0; r < p; ++r) {
      sc[r] = to_mpi_count(send_counts[r], "redistribution send count");
      sd[r] = to_mpi_count(st, "redistribution send displacement");
      rc[r] = to_mpi_count(recv_counts[r], "redistribution receive count");
      rd[r] = to_mpi_count(rt, "redistribution receive displacement");
      st += send_counts[r];
      rt += recv_counts[r];
    }
    HostVector<T> recv(rt);
    RecordType type(sizeof(T));
    CG_MPI(MPI_Alltoallv(send.data(), sc.data(), sd.data(), type.get(), recv.data(), rc.data(), rd.data(),
                         type.get(), m_s.comm));
    return recv;
  }

  // Point-to-point exchange (the halo): every Irecv posted, then every Isend, then one Waitall.
  // Only ranks with a non-zero count take part; this rank's own part (none for a halo) is copied.
  template <class T>
  HostVector<T> exchange(const HostVector<T>& send, const std::vector<std::uint64_t>& send_counts,
                         const std::vector<std::uint64_t>& recv_counts) const {
    std::uint64_t total = 0;
    for (const std::uint64_t c : recv_counts) total += c;
    HostVector<T> recv(total);
    exchange_rows_into(reinterpret_cast<const std::byte*>(send.data()),
                       reinterpret_cast<std::byte*>(recv.data()), sizeof(T), send_counts, recv_counts);
    return recv;
  }

  // The same exchange of rows of `row_bytes` bytes between caller-owned buffers (page-locked ones: the
  // engine's packed rows; any records: collectives.hpp's alltoallv_records), `recv` holding the
  // received rows.
  void exchange_rows_into(const std::byte* send, std::byte* recv, std::size_t row_bytes,
                          const std::vector<std::uint64_t>& send_counts,
                          const std::vector<std::uint64_t>& recv_counts) const {
    const std::size_t p = send_counts.size(), me = static_cast<std::size_t>(m_s.rank);
    std::vector<std::uint64_t> sd(p + 1, 0), rd(p + 1, 0);
    for (std::size_t r = 0; r < p; ++r) {
      sd[r + 1] = sd[r] + send_counts[r];
      rd[r + 1] = rd[r] + recv_counts[r];
    }
    if (send_counts[me] > 0)
      std::memcpy(recv + rd[me] * row_bytes, send + sd[me] * row_bytes, send_counts[me] * row_bytes);
    if (!m_s.mpi) return;
    RecordType type(row_bytes);
    std::vector<MPI_Request> requests;
    for (std::size_t r = 0; r < p; ++r) {
      if (r == me || recv_counts[r] == 0) continue;
      requests.emplace_back();
      CG_MPI(MPI_Irecv(recv + rd[r] * row_bytes, to_mpi_count(recv_counts[r], "halo receive count"),
                       type.get(), static_cast<int>(r), k_halo_tag, m_s.comm, &requests.back()));
    }
    for (std::size_t r = 0; r < p; ++r) {
      if (r == me || send_counts[r] == 0) continue;
      requests.emplace_back();
      CG_MPI(MPI_Isend(send + sd[r] * row_bytes, to_mpi_count(send_counts[r], "halo send count"), type.get(),
                       static_cast<int>(r), k_halo_tag, m_s.comm, &requests.back()));
    }
    if (!requests.empty()) {
      CG_MPI(MPI_Waitall(static_cast<int>(requests.size()), requests.data(), MPI_STATUSES_IGNORE));
    }
  }

  // Rank 0 receives rank r's `n` elements (counts[r], known to all ranks) at `into[r]` (r >= 1; rank
  // 0's own part stays where it is): straight into the final arrays, no staging buffer, no
  // displacement limit. Point-to-point in messages of at most max_bytes (capped to 2^31 - 1): every
  // Irecv posted, then one Waitall (non-root ranks send their messages in order, blocking).
  template <class T>
  void gather_to_root(const T* local, const std::vector<std::uint64_t>& counts, const std::vector<T*>& into,
                      std::uint64_t max_bytes, int tag) const {
    static_assert(std::is_trivially_copyable_v<T>);
    if (!m_s.mpi || m_s.size == 1) return;
    const std::uint64_t budget = std::min<std::uint64_t>(max_bytes, static_cast<std::uint64_t>(INT_MAX));
    const std::uint64_t chunk = std::max<std::uint64_t>(1, budget / sizeof(T));  // elements per message
    RecordType type(sizeof(T));
    if (m_s.rank == 0) {
      std::vector<MPI_Request> requests;
      for (std::size_t r = 1; r < counts.size(); ++r) {
        for (std::uint64_t at = 0; at < counts[r]; at += chunk) {
          requests.emplace_back();
          CG_MPI(MPI_Irecv(into[r] + at, static_cast<int>(std::min(chunk, counts[r] - at)), type.get(),
                           static_cast<int>(r), tag, m_s.comm, &requests.back()));
        }
      }
      if (!requests.empty()) {
        CG_MPI(MPI_Waitall(static_cast<int>(requests.size()), requests.data(), MPI_STATUSES_IGNORE));
      }
    } else {
      const std::uint64_t n = counts[static_cast<std::size_t>(m_s.rank)];
      for (std::uint64_t at = 0; at < n; at += chunk) {
        CG_MPI(MPI_Send(local + at, static_cast<int>(std::min(chunk, n - at)), type.get(), 0, tag, m_s.comm));
      }
    }
  }

  // One field of a contact exchange: the rows this rank sends (rows [split[d], split[d + 1]) go to
  // rank d) and where rank r's rows land here (into[r], r != this rank; this rank's own part is not
  // copied).
  struct RowField {
    const unsigned char* send = nullptr;
    std::vector<unsigned char*> into;
    std::size_t row_bytes = 0;
  };

  // Every field's rows to their destinations: every Irecv posted (per field, source and message),
  // then every Isend (destinations from the next rank on, so the ranks do not all start with rank
  // 0), one Waitall. Messages hold whole rows, at most max_bytes (capped to 2^31 - 1 bytes), sent as
  // MPI_BYTE; a tag per field (MPI keeps the order of messages of one tag and pair).
  void exchange_rows(const std::vector<RowField>& fields, const std::vector<std::uint64_t>& split,
                     const std::vector<std::uint64_t>& recv_counts, std::uint64_t max_bytes, int tag) const {
    if (!m_s.mpi || m_s.size == 1) return;
    const std::uint64_t budget = std::min<std::uint64_t>(max_bytes, static_cast<std::uint64_t>(INT_MAX));
    const std::size_t p = recv_counts.size(), me = static_cast<std::size_t>(m_s.rank);
    std::vector<MPI_Request> requests;
    for (std::size_t f = 0; f < fields.size(); ++f) {
      const RowField& field = fields[f];
      const std::uint64_t chunk = std::max<std::uint64_t>(1, budget / field.row_bytes);  // rows per message
      for (std::size_t r = 0; r < p; ++r) {
        if (r == me) continue;
        for (std::uint64_t at = 0; at < recv_counts[r]; at += chunk) {
          requests.emplace_back();
          CG_MPI(MPI_Irecv(field.into[r] + at * field.row_bytes,
                           static_cast<int>(std::min(chunk, recv_counts[r] - at) * field.row_bytes), MPI_BYTE,
                           static_cast<int>(r), tag + static_cast<int>(f), m_s.comm, &requests.back()));
        }
      }
    }
    for (std::size_t f = 0; f < fields.size(); ++f) {
      const RowField& field = fields[f];
      const std::uint64_t chunk = std::max<std::uint64_t>(1, budget / field.row_bytes);
      for (std::size_t k = 1; k < p; ++k) {
        const std::size_t d = (me + k) % p;
        const std::uint64_t n = split[d + 1] - split[d];
        for (std::uint64_t at = 0; at < n; at += chunk) {
          requests.emplace_back();
          CG_MPI(MPI_Isend(field.send + (split[d] + at) * field.row_bytes,
                           static_cast<int>(std::min(chunk, n - at) * field.row_bytes), MPI_BYTE,
                           static_cast<int>(d), tag + static_cast<int>(f), m_s.comm, &requests.back()));
        }
      }
    }
    if (!requests.empty()) {
      CG_MPI(MPI_Waitall(static_cast<int>(requests.size()), requests.data(), MPI_STATUSES_IGNORE));
    }
  }

  void allreduce_sum(std::vector<std::uint64_t>& values) const {
    if (!m_s.mpi) return;
    CG_MPI(MPI_Allreduce(MPI_IN_PLACE, values.data(), static_cast<int>(values.size()), MPI_UINT64_T, MPI_SUM,
                         m_s.comm));
  }

  void allreduce_max(std::vector<double>& values) const {
    if (!m_s.mpi) return;
    CG_MPI(MPI_Allreduce(MPI_IN_PLACE, values.data(), static_cast<int>(values.size()), MPI_DOUBLE, MPI_MAX,
                         m_s.comm));
  }

 private:
  const Session::Impl& m_s;
};

}  // namespace cg::detail
