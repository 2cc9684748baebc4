// Distributed detection (see distributed_detect.hpp): read own rows → shared frame → slabs →
// redistribute to owners → ghost exchange → engine on owned + ghosts (the owner of the smaller id
// reports) → contacts exchanged by id_a range (or gathered to rank 0) → parallel k-way merge by
// (id_a, id_b).
#include "distributed_detect.hpp"

#include <omp.h>
#include <sys/mman.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <limits>
#include <new>
#include <numeric>
#include <optional>
#include <queue>
#include <thread>
#include <tuple>
#include <type_traits>
#include <utility>

#include "backend.hpp"
#include "contact_merge.hpp"
#include "hdf5_io.hpp"
#include "mpi_detail.hpp"

namespace cg {

namespace {
// The engine's stage names (both backends), in pipeline order ("upload": CUDA only).
const std::vector<std::string> k_engine_stages{"plan",  "upload", "pack",   "entries", "sort",
                                               "pairs", "order",  "narrow", "download"};
}  // namespace

void validate(const DistributedOptions& options) {
  const EngineOptions& e = options.engine;
  if (options.axis < -1 || options.axis > 2) {
    throw UsageError("--axis: " + std::to_string(options.axis) + " is not x, y, z or auto");
  }
  if (options.balance != Balance::count && options.balance != Balance::width) {
    throw UsageError("--balance: not one of count, width");
  }
  if (!std::isfinite(e.cell_size) || e.cell_size < 0) {
    throw UsageError("--cell-size: must be a finite length >= 0 (0: chosen by cell_choice)");
  }
  if (e.threads < 0) throw UsageError("--threads: must be >= 0 (0: all hardware threads)");
  if (options.max_sample < 1) throw UsageError("max_sample: must be >= 1");
  if (options.max_message_bytes < 64) throw UsageError("max_message_bytes: must be >= 64");
  if (options.resident_steps < 0) throw UsageError("--steps: must be >= 0");
}

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// An array of n trivially copyable T, NOT value-initialised: receive buffers and the engine's input
// are overwritten entirely, so the zero-fill pass of std::vector would be a wasted sweep of memory
// (and its single-threaded first touch). Large ones are 2 MiB aligned and offered to transparent
// huge pages (where the kernel has them on madvise), so their first touch takes few page faults.
// Move-only.
template <class T>
class Buffer {
  static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>);
  static constexpr std::size_t k_huge = std::size_t(2) << 20;

 public:
  Buffer() = default;
  explicit Buffer(std::size_t n) : m_n(n) {
    if (n == 0) return;
    const std::size_t bytes = n * sizeof(T);
    m_align = bytes >= 2 * k_huge ? k_huge : alignof(T);
    m_p = static_cast<T*>(::operator new(bytes, std::align_val_t(m_align)));
#if defined(MADV_HUGEPAGE)
    if (m_align == k_huge && detail::huge_pages_wanted())
      ::madvise(static_cast<void*>(m_p), bytes / k_huge * k_huge, MADV_HUGEPAGE);
#endif
  }
  ~Buffer() { release(); }
  Buffer(Buffer&& o) noexcept
      : m_p(std::exchange(o.m_p, nullptr)), m_n(std::exchange(o.m_n, 0)), m_align(o.m_align) {}
  Buffer& operator=(Buffer&& o) noexcept {
    if (this != &o) {
      release();
      m_p = std::exchange(o.m_p, nullptr);
      m_n = std::exchange(o.m_n, 0);
      m_align = o.m_align;
    }
    return *this;
  }
  T* data() { return m_p; }
  const T* data() const { return m_p; }
  std::size_t size() const { return m_n; }
  T& operator[](std::size_t i) { return m_p[i]; }
  const T& operator[](std::size_t i) const { return m_p[i]; }
  std::span<const T> span() const { return {m_p, m_n}; }

 private:
  void release() {
    if (m_p) ::operator delete(m_p, std::align_val_t(m_align));
    m_p = nullptr;
    m_n = 0;
  }
  T* m_p = nullptr;
  std::size_t m_n = 0;
  std::size_t m_align = alignof(T);
};

// Host threads of this rank (its comm loops and its engine): the engine's --threads, or when 0 an
// equal share of the node's hardware threads among the ranks on the node. Each rank taking every
// core (the old default) oversubscribed a node P times under `mpirun --bind-to none`: P OpenMP teams
// of one thread per core, whose barriers wait for descheduled threads.
int host_threads(const DistributedOptions& o, const Session& s) {
  if (o.engine.threads > 0) return o.engine.threads;
  static const int node_threads = omp_get_max_threads();  // before any run set the default (below)
  return std::max(1, node_threads / std::max(1, s.local_size()));
}

// For one run, this rank's share is also OpenMP's default team size, so that every parallel loop
// that asks omp_get_max_threads() (the scene reader, compute_bounds, the CUDA download's copy, ...)
// takes the share too. Without it, two ranks on a 32-thread node ran 32-thread loops each, and their
// spinning barriers made the np 2 read 4x slower than np 1's (2^26 on the 2-GPU host).
class DefaultTeam {
 public:
  explicit DefaultTeam(int threads) : m_saved(omp_get_max_threads()) { omp_set_num_threads(threads); }
  ~DefaultTeam() { omp_set_num_threads(m_saved); }
  DefaultTeam(const DefaultTeam&) = delete;
  DefaultTeam& operator=(const DefaultTeam&) = delete;

 private:
  int m_saved;
};

// Static split of [0, n) into `parts` contiguous chunks (deterministic, whatever the team size).
struct Chunks {
  std::size_t n;
  int parts;
  Chunks(std::size_t n_, int threads)
      : n(n_), parts(n_ < (std::size_t(1) << 14) ? 1 : std::max(1, threads)) {}
  std::size_t begin(int t) const { return static_cast<std::size_t>((std::uint64_t)n * t / parts); }
  std::size_t end(int t) const { return begin(t + 1); }
};

// Smallest i in [0, n) with bad(i), or n. Parallel; the answer does not depend on the threads.
template <class Bad>
std::size_t first_bad(std::size_t n, int threads, Bad&& bad) {
  const Chunks c(n, threads);
  std::vector<std::size_t> found(static_cast<std::size_t>(c.parts), n);
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    for (std::size_t i = c.begin(t), e = c.end(t); i < e; ++i) {
      if (bad(i)) {
        found[static_cast<std::size_t>(t)] = i;
        break;
      }
    }
  }
  return *std::min_element(found.begin(), found.end());
}

// One body in flight between ranks. General over body kinds: a global id and a bounding sphere
// (ellipsoids will add their shape here).
struct BodyRecord {
  Vec3<double> position;
  double radius;
  std::int64_t id;
};
static_assert(std::is_trivially_copyable_v<BodyRecord>);

// Bodies 0 … n-1 grouped by destination rank, in one pass of counting and one of filling (per-thread
// counts → scan → fill, no index list): `dest(i, emit)` calls emit(r) for each destination rank of
// body i, `make(i)` is its record. Within a destination, bodies keep ascending i (the order of the
// sequential count → scan → fill of decomposition/build_plan). counts[r]: the records for rank r.
template <class Dest, class Make>
Buffer<BodyRecord> route(std::size_t n, int ranks, int threads, std::vector<std::uint64_t>& counts,
                         Dest&& dest, Make&& make) {
  const std::size_t p = static_cast<std::size_t>(ranks);
  const Chunks c(n, threads);
  const std::size_t parts = static_cast<std::size_t>(c.parts);
  std::vector<std::uint64_t> at(parts * p, 0);  // per chunk and rank: count, then first slot
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    std::uint64_t* mine = at.data() + static_cast<std::size_t>(t) * p;
    for (std::size_t i = c.begin(t), e = c.end(t); i < e; ++i) dest(i, [&](int r) { ++mine[r]; });
  }
  counts.assign(p, 0);
  std::uint64_t total = 0;
  for (std::size_t r = 0; r < p; ++r) {
    for (std::size_t t = 0; t < parts; ++t) {
      const std::uint64_t k = at[t * p + r];
      at[t * p + r] = total;
      total += k;
      counts[r] += k;
    }
  }
  Buffer<BodyRecord> out(total);
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    std::uint64_t* next = at.data() + static_cast<std::size_t>(t) * p;
    for (std::size_t i = c.begin(t), e = c.end(t); i < e; ++i)
      dest(i, [&](int r) { out[next[r]++] = make(i); });
  }
  return out;
}

// The engine's input in id order: positions, radii, ids, report mask (1: owned).
struct EngineInput {
  Buffer<Vec3<double>> position;
  Buffer<double> radius;
  Buffer<std::int64_t> id;
  Buffer<std::uint8_t> report;
};

double component(const Vec3<double>& v, int k) { return k == 0 ? v.x : (k == 1 ? v.y : v.z); }

// Every-row read: rank `me`'s engine input straight from all N rows (row = id): its owned bodies
// (report 1) and every other body within the ghost width of its slab (report 0), ascending id — the
// bodies that redistribution and the halo exchange bring, by the same owner() and
// for_each_ghost_rank() tests, without moving any. Parallel count → scan → fill.
EngineInput select_owned_and_ghosts(std::span<const Vec3<double>> position, std::span<const double> radius,
                                    const SlabDecomposition& s, int axis, double width, int me, int threads,
                                    std::uint64_t& n_owned, std::uint64_t& n_ghosts) {
  const std::size_t n = position.size();
  // 0: not held here, 1: ghost, 2: owned
  auto held = [&](std::size_t i) {
    const double x = component(position[i], axis);
    if (s.owner(x) == me) return 2;
    int h = 0;
    s.for_each_ghost_rank(x, width, [&](int r) { h |= r == me; });
    return h;
  };
  const Chunks c(n, threads);
  std::vector<std::uint64_t> at(static_cast<std::size_t>(c.parts) + 1, 0), owned(at.size(), 0);
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    std::uint64_t k = 0, o = 0;
    for (std::size_t i = c.begin(t), e = c.end(t); i < e; ++i) {
      const int h = held(i);
      k += h != 0;
      o += h == 2;
    }
    at[static_cast<std::size_t>(t) + 1] = k;
    owned[static_cast<std::size_t>(t) + 1] = o;
  }
  for (std::size_t t = 1; t < at.size(); ++t) at[t] += at[t - 1], owned[t] += owned[t - 1];
  const std::uint64_t total = at.back();
  n_owned = owned.back();
  n_ghosts = total - n_owned;
  EngineInput in{Buffer<Vec3<double>>(total), Buffer<double>(total), Buffer<std::int64_t>(total),
                 Buffer<std::uint8_t>(total)};
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    std::uint64_t w = at[static_cast<std::size_t>(t)];
    for (std::size_t i = c.begin(t), e = c.end(t); i < e; ++i) {
      const int h = held(i);
      if (h == 0) continue;
      in.position[w] = position[i];
      in.radius[w] = radius[i];
      in.id[w] = static_cast<std::int64_t>(i);
      in.report[w] = h == 2;
      ++w;
    }
  }
  return in;
}

// Owned bodies (ascending id: they arrive grouped by source rank, each source sends a subsequence of
// its contiguous row range) and ghosts (grouped by source rank, each group ascending) merged by id
// straight into the engine's arrays: the ghost groups k-way merged (a few, small), then a parallel
// two-way merge with the owned run (owned split into chunks, the ghost run split by binary search).
// Throws if an id is held twice or the order is broken (internal errors).
EngineInput merge_by_id(const Buffer<BodyRecord>& owned, const Buffer<BodyRecord>& ghosts,
                        const std::vector<std::uint64_t>& ghost_counts, int threads) {
  // ghost groups → one ascending run
  Buffer<BodyRecord> g(ghosts.size());
  {
    using Head = std::pair<std::int64_t, std::size_t>;  // (id, group)
    std::priority_queue<Head, std::vector<Head>, std::greater<Head>> heap;
    std::vector<std::uint64_t> next, end;
    std::uint64_t at = 0;
    for (std::uint64_t k : ghost_counts) {
      if (k > 0) {
        heap.emplace(ghosts[at].id, next.size());
        next.push_back(at);
        end.push_back(at + k);
      }
      at += k;
    }
    std::size_t w = 0;
    while (!heap.empty()) {
      const std::size_t r = heap.top().second;
      heap.pop();
      g[w++] = ghosts[next[r]++];
      if (next[r] < end[r]) heap.emplace(ghosts[next[r]].id, r);
    }
  }
  const std::size_t no = owned.size(), ng = g.size(), n = no + ng;
  EngineInput in{Buffer<Vec3<double>>(n), Buffer<double>(n), Buffer<std::int64_t>(n),
                 Buffer<std::uint8_t>(n)};
  auto ghost_split = [&](std::size_t a) -> std::size_t {  // ghosts before owned[a]
    if (a == 0) return 0;
    if (a == no) return ng;
    const std::int64_t id = owned[a].id;
    return static_cast<std::size_t>(
        std::lower_bound(g.data(), g.data() + ng, id,
                         [](const BodyRecord& b, std::int64_t v) { return b.id < v; }) -
        g.data());
  };
  const Chunks c(std::max(no, ng), threads);
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (c.parts > 1)
  for (int t = 0; t < c.parts; ++t) {
    std::size_t a = static_cast<std::size_t>((std::uint64_t)no * t / c.parts);
    const std::size_t a_end = static_cast<std::size_t>((std::uint64_t)no * (t + 1) / c.parts);
    std::size_t b = ghost_split(a);
    const std::size_t b_end = t + 1 == c.parts ? ng : ghost_split(a_end);
    std::size_t k = a + b;
    auto put = [&](const BodyRecord& x, std::uint8_t mine) {
      in.position[k] = x.position;
      in.radius[k] = x.radius;
      in.id[k] = x.id;
      in.report[k] = mine;
      ++k;
    };
    while (a < a_end && b < b_end) {
      if (g[b].id < owned[a].id) {
        put(g[b++], 0);
      } else {
        put(owned[a++], 1);
      }
    }
    while (a < a_end) put(owned[a++], 1);
    while (b < b_end) put(g[b++], 0);
  }
  const std::int64_t* id = in.id.data();
  const std::size_t k =
      first_bad(n > 0 ? n - 1 : 0, threads, [&](std::size_t i) { return !(id[i + 1] > id[i]); });
  if (k + 1 < n) {
    if (id[k + 1] == id[k]) {
      throw Error("body " + std::to_string(id[k]) + " is held twice (owned and ghost): internal error");
    }
    throw Error("bodies are not in id order at " + std::to_string(k + 1) + ": internal error");
  }
  return in;
}

// Bounds of one rank, as exchanged (count 0: the rank read no body and is skipped).
struct BoundsRecord {
  Vec3<double> lo, hi;
  double r_max;
  std::uint64_t count;
  double r_sum[3];  // radius moments (the tuned cell size)
};
static_assert(std::is_trivially_copyable_v<BoundsRecord>);

constexpr int k_halo_tag = 7301;
constexpr int k_gather_tag = 7400;    // + field index
constexpr int k_exchange_tag = 7500;  // + field index

// The collectives of distributed_detect over the session's communicator. In laptop mode (no MPI)
// they are the one-rank identities, so one rank runs the same code path with no neighbours.
// Element types are trivially copyable and sent as bytes (homogeneous nodes).
class Comm {
 public:
  explicit Comm(const Session& session) : m_s(session.impl()) {}
  int rank() const { return m_s.rank; }
  int size() const { return m_s.size; }

  template <class T>
  std::vector<T> allgather(const T& value) const {
    if (!m_s.mpi) return {value};
    std::vector<T> out(static_cast<std::size_t>(m_s.size));
    detail::RecordType type(sizeof(T));
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
      counts[r] = detail::to_mpi_count(n[r], "all-gather count");
      displs[r] = detail::to_mpi_count(total, "all-gather displacement");
      total += n[r];
    }
    std::vector<T> out(total);
    detail::RecordType type(sizeof(T));
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
  Buffer<T> alltoallv(Buffer<T>&& send, const std::vector<std::uint64_t>& send_counts,
                      const std::vector<std::uint64_t>& recv_counts) const {
    if (!m_s.mpi || m_s.size == 1) return std::move(send);
    const std::size_t p = send_counts.size();
    std::vector<int> sc(p), sd(p), rc(p), rd(p);
    std::uint64_t st = 0, rt = 0;
    for (std::size_t r = 0; r < p; ++r) {
      sc[r] = detail::to_mpi_count(send_counts[r], "redistribution send count");
      sd[r] = detail::to_mpi_count(st, "redistribution send displacement");
      rc[r] = detail::to_mpi_count(recv_counts[r], "redistribution receive count");
      rd[r] = detail::to_mpi_count(rt, "redistribution receive displacement");
      st += send_counts[r];
      rt += recv_counts[r];
    }
    Buffer<T> recv(rt);
    detail::RecordType type(sizeof(T));
    CG_MPI(MPI_Alltoallv(send.data(), sc.data(), sd.data(), type.get(), recv.data(), rc.data(), rd.data(),
                         type.get(), m_s.comm));
    return recv;
  }

  // Point-to-point exchange (the halo): every Irecv posted, then every Isend, then one Waitall.
  // Only ranks with a non-zero count take part; this rank's own part (none for a halo) is copied.
  template <class T>
  Buffer<T> exchange(const Buffer<T>& send, const std::vector<std::uint64_t>& send_counts,
                     const std::vector<std::uint64_t>& recv_counts) const {
    const std::size_t p = send_counts.size(), me = static_cast<std::size_t>(m_s.rank);
    std::vector<std::uint64_t> sd(p + 1, 0), rd(p + 1, 0);
    for (std::size_t r = 0; r < p; ++r) {
      sd[r + 1] = sd[r] + send_counts[r];
      rd[r + 1] = rd[r] + recv_counts[r];
    }
    Buffer<T> recv(rd[p]);
    if (send_counts[me] > 0)
      std::memcpy(recv.data() + rd[me], send.data() + sd[me], send_counts[me] * sizeof(T));
    if (!m_s.mpi) return recv;
    detail::RecordType type(sizeof(T));
    std::vector<MPI_Request> requests;
    for (std::size_t r = 0; r < p; ++r) {
      if (r == me || recv_counts[r] == 0) continue;
      requests.emplace_back();
      CG_MPI(MPI_Irecv(recv.data() + rd[r], detail::to_mpi_count(recv_counts[r], "halo receive count"),
                       type.get(), static_cast<int>(r), k_halo_tag, m_s.comm, &requests.back()));
    }
    for (std::size_t r = 0; r < p; ++r) {
      if (r == me || send_counts[r] == 0) continue;
      requests.emplace_back();
      CG_MPI(MPI_Isend(send.data() + sd[r], detail::to_mpi_count(send_counts[r], "halo send count"),
                       type.get(), static_cast<int>(r), k_halo_tag, m_s.comm, &requests.back()));
    }
    if (!requests.empty()) {
      CG_MPI(MPI_Waitall(static_cast<int>(requests.size()), requests.data(), MPI_STATUSES_IGNORE));
    }
    return recv;
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
    detail::RecordType type(sizeof(T));
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

  void allreduce_max(std::vector<double>& values) const {
    if (!m_s.mpi) return;
    CG_MPI(MPI_Allreduce(MPI_IN_PLACE, values.data(), static_cast<int>(values.size()), MPI_DOUBLE, MPI_MAX,
                         m_s.comm));
  }

 private:
  const Session::Impl& m_s;
};

// Runs the local part of a stage; afterwards every rank agrees on whether any rank failed.
template <class F>
void local_stage(const Session& session, const char* stage, F&& work) {
  std::exception_ptr error;
  try {
    work();
  } catch (...) {
    error = std::current_exception();
  }
  session.agree(error, stage);
}

// root mode: the ranks' contacts gathered to rank 0 and merged there (see the file comment).
// Receive storage for one run of n contacts (ids, distance and nvec vector fields) and its view.
template <class Real>
ContactRunView<Real> receive_run(std::size_t n, int nvec, Buffer<std::int64_t>& id_a,
                                 Buffer<std::int64_t>& id_b, Buffer<Real>& distance,
                                 std::vector<Buffer<Vec3<Real>>>& vec) {
  id_a = Buffer<std::int64_t>(n);
  id_b = Buffer<std::int64_t>(n);
  distance = Buffer<Real>(n);
  for (int f = 0; f < nvec; ++f) vec.emplace_back(n);
  ContactRunView<Real> run;
  run.n = n;
  run.id_a = id_a.data();
  run.id_b = id_b.data();
  run.distance = distance.data();
  for (int f = 0; f < nvec; ++f) run.vec[f] = vec[static_cast<std::size_t>(f)].data();
  return run;
}

template <class Real>
void gather_and_merge(const Session& session, const Comm& comm, Contacts<Real>& local,
                      const DistributedOptions& options, int threads, DistributedResult<Real>& result,
                      std::vector<double>& times) {
  const int ranks = comm.size(), me = comm.rank();
  const bool alone = ranks == 1, full = options.engine.fields == Fields::full;
  // ---- gather: each field to rank 0, straight into per-rank receive buffers ---------------------
  auto t0 = Clock::now();
  const std::vector<std::uint64_t> counts =
      alone ? std::vector<std::uint64_t>{local.size()} : comm.allgather<std::uint64_t>(local.size());
  const std::size_t p = counts.size();
  std::vector<ContactRunView<Real>> runs;
  // rank 0's received fields: ids (2), distance, and up to 7 vector fields per rank
  std::vector<Buffer<std::int64_t>> recv_a, recv_b;
  std::vector<Buffer<Real>> recv_d;
  std::vector<std::vector<Buffer<Vec3<Real>>>> recv_v;
  const int nvec = full ? 7 : 3;
  if (!alone) {
    const bool root = me == 0;
    if (root) {
      runs.resize(p);
      recv_a.resize(p);
      recv_b.resize(p);
      recv_d.resize(p);
      recv_v.resize(p);
      runs[0] = contact_run_view(local, full);  // rank 0's own run stays in place
      for (std::size_t r = 1; r < p; ++r) {
        runs[r] = receive_run(counts[r], nvec, recv_a[r], recv_b[r], recv_d[r], recv_v[r]);
      }
    }
    auto targets = [&](auto& buffers) {  // where rank r's part of a field lands on rank 0 (r >= 1)
      std::vector<decltype(buffers[0].data())> t(root ? p : 0, nullptr);
      for (std::size_t r = 1; root && r < p; ++r) t[r] = buffers[r].data();
      return t;
    };
    comm.gather_to_root(local.id_a.data(), counts, targets(recv_a), options.max_message_bytes,
                        k_gather_tag + 0);
    comm.gather_to_root(local.id_b.data(), counts, targets(recv_b), options.max_message_bytes,
                        k_gather_tag + 1);
    comm.gather_to_root(local.distance.data(), counts, targets(recv_d), options.max_message_bytes,
                        k_gather_tag + 2);
    for (int f = 0; f < nvec; ++f) {
      std::vector<Vec3<Real>*> t(root ? p : 0, nullptr);
      for (std::size_t r = 1; root && r < p; ++r) t[r] = recv_v[r][static_cast<std::size_t>(f)].data();
      comm.gather_to_root(contact_vec_field(local, f)->data(), counts, t, options.max_message_bytes,
                          k_gather_tag + 3 + f);
    }
    if (!root) local = Contacts<Real>{};
  }
  times[4] = seconds_since(t0);

  // ---- merge (rank 0): k-way merge of the sorted runs, duplicates removed and counted -----------
  t0 = Clock::now();
  local_stage(session, "merge", [&] {
    if (me != 0) return;
    if (alone) {
      result.contacts = std::move(local);  // one sorted run: nothing to merge
    } else {
      std::uint64_t total = 0;
      for (std::uint64_t k : counts) total += k;
      result.contacts.resize(total, full);
      const int parts = total < (std::uint64_t(1) << 15) ? 1 : 4 * threads;  // a few per thread: balance
      result.duplicates_removed = merge_contact_runs_into<Real>(runs, result.contacts, full, parts, threads);
      runs.clear();
      local = Contacts<Real>{};
    }
    const std::string line = "merge: " + std::to_string(result.contacts.size()) + " contacts from " +
                             std::to_string(ranks) + " rank(s), " +
                             std::to_string(result.duplicates_removed) + " duplicate(s) removed (expected 0)";
    if (options.log) {
      options.log(line);
    } else if (result.duplicates_removed > 0) {  // a warning nobody asked for must still be seen
      std::fprintf(stderr, "%swarning: %s\n", session.prefix().c_str(), line.c_str());
    }
  });
  times[5] = seconds_since(t0);
  result.total_contacts = session.sum(me == 0 ? result.contacts.size() : 0);
  result.first_row = me == 0 ? 0 : result.total_contacts;
  result.id_begin = me == 0 ? 0 : result.bodies;
  result.id_end = result.bodies;
}

// id_ranges mode: every rank ends with the merged contacts of its id_a range (see the file comment).
template <class Real>
void exchange_and_merge(const Session& session, const Comm& comm, Contacts<Real>& local,
                        std::uint64_t n_global, const DistributedOptions& options, int threads,
                        DistributedResult<Real>& result, std::vector<double>& times) {
  const int ranks = comm.size(), me = comm.rank();
  const std::size_t p = static_cast<std::size_t>(ranks), mine = static_cast<std::size_t>(me);
  const bool full = options.engine.fields == Fields::full;
  const int nvec = full ? 7 : 3;
  // the id_a range of rank d: the rows it read
  auto id_begin = [&](std::size_t d) { return n_global * d / p; };
  result.id_begin = id_begin(mine);
  result.id_end = id_begin(mine + 1);

  // ---- exchange: each destination's slice of every field, straight from the arrays --------------
  auto t0 = Clock::now();
  std::vector<std::uint64_t> split(p + 1, 0), send_counts(p, 0);
  local_stage(session, "exchange", [&] {
    // sorted by (id_a, id_b), so rank d's rows are one sub-range
    split[p] = local.size();
    for (std::size_t d = 1; d < p; ++d) {
      const auto at =
          std::lower_bound(local.id_a.begin(), local.id_a.end(), static_cast<std::int64_t>(id_begin(d)));
      split[d] = static_cast<std::uint64_t>(at - local.id_a.begin());
    }
    for (std::size_t d = 0; d < p; ++d) send_counts[d] = split[d + 1] - split[d];
  });
  const std::vector<std::uint64_t> recv_counts = comm.alltoall_counts(send_counts);
  std::vector<ContactRunView<Real>> runs(p);
  std::vector<Buffer<std::int64_t>> recv_a(p), recv_b(p);
  std::vector<Buffer<Real>> recv_d(p);
  std::vector<std::vector<Buffer<Vec3<Real>>>> recv_v(p);
  std::vector<Comm::RowField> fields(3 + static_cast<std::size_t>(nvec));
  local_stage(session, "exchange", [&] {
    for (std::size_t r = 0; r < p; ++r) {
      if (r == mine) {  // this rank's own part stays where it is
        const std::uint64_t at = split[mine];
        ContactRunView<Real>& v = runs[r];
        v.n = send_counts[mine];
        v.id_a = local.id_a.data() + at;
        v.id_b = local.id_b.data() + at;
        v.distance = local.distance.data() + at;
        for (int f = 0; f < nvec; ++f) v.vec[f] = contact_vec_field(local, f)->data() + at;
        continue;
      }
      runs[r] = receive_run(recv_counts[r], nvec, recv_a[r], recv_b[r], recv_d[r], recv_v[r]);
    }
    auto bytes = [](auto* ptr) { return reinterpret_cast<unsigned char*>(ptr); };
    auto cbytes = [](const auto* ptr) { return reinterpret_cast<const unsigned char*>(ptr); };
    for (auto& field : fields) field.into.assign(p, nullptr);
    fields[0].send = cbytes(local.id_a.data());
    fields[0].row_bytes = sizeof(std::int64_t);
    fields[1].send = cbytes(local.id_b.data());
    fields[1].row_bytes = sizeof(std::int64_t);
    fields[2].send = cbytes(local.distance.data());
    fields[2].row_bytes = sizeof(Real);
    for (int f = 0; f < nvec; ++f) {
      fields[3 + static_cast<std::size_t>(f)].send = cbytes(contact_vec_field(local, f)->data());
      fields[3 + static_cast<std::size_t>(f)].row_bytes = sizeof(Vec3<Real>);
    }
    for (std::size_t r = 0; r < p; ++r) {
      if (r == mine) continue;
      fields[0].into[r] = bytes(recv_a[r].data());
      fields[1].into[r] = bytes(recv_b[r].data());
      fields[2].into[r] = bytes(recv_d[r].data());
      for (int f = 0; f < nvec; ++f)
        fields[3 + static_cast<std::size_t>(f)].into[r] =
            bytes(recv_v[r][static_cast<std::size_t>(f)].data());
    }
  });
  comm.exchange_rows(fields, split, recv_counts, options.max_message_bytes, k_exchange_tag);
  times[4] = seconds_since(t0);

  // ---- merge: the P sorted runs of this rank's id range, duplicates removed and counted ----------
  t0 = Clock::now();
  std::uint64_t duplicates = 0;
  local_stage(session, "merge", [&] {
    if (p == 1) {
      result.contacts = std::move(local);  // one sorted run: nothing to merge
      return;
    }
    std::uint64_t total = 0;
    for (std::uint64_t k : recv_counts) total += k;
    Contacts<Real> merged;
    merged.resize(total, full);
    const int parts = total < (std::uint64_t(1) << 15) ? 1 : 4 * threads;  // a few per thread: balance
    duplicates = merge_contact_runs_into<Real>(runs, merged, full, parts, threads);
    runs.clear();
    local = Contacts<Real>{};
    result.contacts = std::move(merged);
  });
  times[5] = seconds_since(t0);
  result.duplicates_removed = session.sum(duplicates);
  const std::vector<std::uint64_t> counts = comm.allgather<std::uint64_t>(result.contacts.size());
  result.first_row = std::accumulate(counts.begin(), counts.begin() + me, std::uint64_t{0});
  result.total_contacts = std::accumulate(counts.begin(), counts.end(), std::uint64_t{0});
  const std::string line = "merge: " + std::to_string(result.total_contacts) + " contacts in " +
                           std::to_string(ranks) + " id range(s), " +
                           std::to_string(result.duplicates_removed) + " duplicate(s) removed (expected 0)";
  if (me == 0) {
    if (options.log) {
      options.log(line);
    } else if (result.duplicates_removed > 0) {  // a warning nobody asked for must still be seen
      std::fprintf(stderr, "%swarning: %s\n", session.prefix().c_str(), line.c_str());
    }
  }
}

// ---- resident steps (see the header comment) ------------------------------------------------------
// An order-free fingerprint of a contact set: the sum over its pairs (splitmix64 of the two ids).
std::uint64_t pair_hash(std::int64_t a, std::int64_t b) {
  std::uint64_t x = static_cast<std::uint64_t>(a) * 0x9E3779B97F4A7C15ull ^ static_cast<std::uint64_t>(b);
  x ^= x >> 30;
  x *= 0xBF58476D1CE4E5B9ull;
  x ^= x >> 27;
  x *= 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// One rank's rows for the steps and where its halo ranges lie.
struct StepLayout {
  std::vector<std::uint64_t> send_counts, recv_counts;  // per rank, fixed for every step
  std::size_t owned = 0;         // owned rows: [down only][both ways][up only][interior] (engine A)
  std::size_t down = 0, up = 0;  // owned rows sent to lower ranks: the first `down`; up: [sent - up, sent)
  std::size_t sent = 0;          // owned rows sent anywhere: the first `sent` (the boundary)
  std::size_t lower_ghosts = 0;  // boundary rows (engine B): [lower ghosts][the `sent` owned][upper ghosts]
};

// Page-locked host memory for an engine's copies (released before the memory is).
template <class Real>
struct Pin {
  Engine<Real>& engine;
  void* p;
  bool pinned;
  Pin(Engine<Real>& e, void* ptr, std::size_t bytes) : engine(e), p(ptr), pinned(e.pin_host(ptr, bytes)) {}
  ~Pin() {
    if (pinned) engine.unpin_host(p);
  }
  Pin(const Pin&) = delete;
  Pin& operator=(const Pin&) = delete;
};

double median_of(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

template <class Real>
StepStats resident_steps(Session& session, const Comm& comm, Engine<Real>& engine, const Frame& frame,
                         const SlabDecomposition* slabs, int axis, double width,
                         std::span<const Vec3<double>> position, std::span<const double> radius,
                         std::span<const std::int64_t> id, std::span<const std::uint8_t> report, int steps,
                         std::uint64_t expected, std::uint64_t expected_hash, int threads) {
  StepStats st;
  st.steps = steps;
  const int ranks = session.size(), me = session.rank();
  const std::size_t p = static_cast<std::size_t>(ranks), n = radius.size(),
                    n_steps = static_cast<std::size_t>(steps);
  const auto t0 = Clock::now();
  StepLayout l;
  l.send_counts.assign(p, 0);
  l.recv_counts.assign(p, 0);
  Buffer<std::int64_t> owned_id;  // engine A's rows → global id
  Buffer<Vec3<double>> b_p;       // engine B's rows, host side (page-locked)
  Buffer<double> b_r;
  Buffer<std::int64_t> b_id;
  std::optional<Engine<Real>> boundary;  // engine B
  std::optional<Pin<Real>> pin_p, pin_r;
  if (!slabs) {  // one rank: every row resident as read, all pairs, no halo
    local_stage(session, "steps", [&] { engine.set_resident(BodiesView{position, radius, {}, {}}); });
  } else {
    std::vector<std::size_t> owned_rows;  // input rows of engine A's rows
    local_stage(session, "steps", [&] {
      Buffer<std::uint8_t> cls(n);
      std::vector<char> need(p, 0);
#pragma omp parallel num_threads(threads)
      {
        std::vector<char> mine(p, 0);
#pragma omp for schedule(static)
        for (std::size_t i = 0; i < n; ++i) {
          if (!report[i]) {
            cls[i] = 4;  // a ghost of the file run
            continue;
          }
          bool down = false, up = false;
          slabs->for_each_ghost_rank(component(position[i], axis), width, [&](int q) {
            mine[static_cast<std::size_t>(q)] = 1;
            (q < me ? down : up) = true;
          });
          cls[i] = down && up ? 1 : down ? 0 : up ? 2 : 3;
        }
#pragma omp critical
        for (std::size_t q = 0; q < p; ++q) need[q] |= mine[q];
      }
      std::size_t count[5] = {0, 0, 0, 0, 0};
      for (std::size_t i = 0; i < n; ++i) ++count[cls[i]];
      std::size_t at[4] = {0, count[0], count[0] + count[1], count[0] + count[1] + count[2]};
      owned_rows.resize(at[3] + count[3]);
      for (std::size_t i = 0; i < n; ++i)
        if (cls[i] < 4) owned_rows[at[cls[i]]++] = i;
      l.owned = owned_rows.size();
      l.down = count[0] + count[1];
      l.up = count[1] + count[2];
      l.sent = count[0] + count[1] + count[2];
      for (std::size_t q = 0; q < p; ++q)
        if (need[q]) l.send_counts[q] = static_cast<int>(q) < me ? l.down : l.up;
      // engine A: the owned rows, all their pairs
      Buffer<Vec3<double>> a_p(l.owned);
      Buffer<double> a_r(l.owned);
      owned_id = Buffer<std::int64_t>(l.owned);
#pragma omp parallel for num_threads(threads) schedule(static)
      for (std::size_t k = 0; k < l.owned; ++k) {
        a_p[k] = position[owned_rows[k]];
        a_r[k] = radius[owned_rows[k]];
        owned_id[k] = id[owned_rows[k]];
      }
      engine.set_resident(BodiesView{a_p.span(), a_r.span(), {}, {}});
    });
    l.recv_counts = comm.alltoall_counts(l.send_counts);
    for (std::size_t q = 0; q < static_cast<std::size_t>(me); ++q) l.lower_ghosts += l.recv_counts[q];
    // the first exchange carries the ghosts' records (ids too); later steps refresh their rows
    Buffer<BodyRecord> send;
    local_stage(session, "steps", [&] {
      std::uint64_t total = 0;
      for (std::uint64_t c : l.send_counts) total += c;
      send = Buffer<BodyRecord>(total);
      std::size_t w = 0;
      for (std::size_t q = 0; q < p; ++q) {
        const std::size_t from = static_cast<int>(q) < me ? 0 : l.sent - l.up;
        for (std::size_t k = from; k < from + l.send_counts[q]; ++k) {
          const std::size_t i = owned_rows[k];
          send[w++] = BodyRecord{position[i], radius[i], id[i]};
        }
      }
    });
    const Buffer<BodyRecord> got = comm.exchange(send, l.send_counts, l.recv_counts);
    local_stage(session, "steps", [&] {
      // engine B: [lower ghosts][boundary owned rows][upper ghosts]; the owned ones are paired with
      // each other by engine A already
      const std::size_t total = l.sent + got.size();
      b_p = Buffer<Vec3<double>>(total);
      b_r = Buffer<double>(total);
      b_id = Buffer<std::int64_t>(total);
      Buffer<std::uint8_t> mask(total);
      for (std::size_t k = 0; k < total; ++k) {
        const bool ghost = k < l.lower_ghosts || k >= l.lower_ghosts + l.sent;
        if (ghost) {
          const BodyRecord& g = got[k < l.lower_ghosts ? k : k - l.sent];
          b_p[k] = g.position;
          b_r[k] = g.radius;
          b_id[k] = g.id;
        } else {
          const std::size_t i = owned_rows[k - l.lower_ghosts];
          b_p[k] = position[i];
          b_r[k] = radius[i];
          b_id[k] = id[i];
        }
        mask[k] = ghost ? 0 : kReportedBit | kPairedBit;
      }
      boundary.emplace(engine.options());
      boundary->set_resident(BodiesView{b_p.span(), b_r.span(), {}, mask.span()});
      pin_p.emplace(engine, b_p.data(), b_p.size() * sizeof(Vec3<double>));
      pin_r.emplace(engine, b_r.data(), b_r.size() * sizeof(double));
    });
    st.halo_rows = got.size();
  }
  st.setup = session.max(seconds_since(t0));
  st.halo_rows = session.sum(st.halo_rows);

  // Each step: the boundary owned rows out of engine A; A detects its owned rows (another thread)
  // while this thread exchanges the halo (MPI only here) and writes engine B's rows, then B detects.
  // Per step (max over ranks): halo, interior (A), boundary (B), step (wall); medians reported.
  std::uint64_t total_send = 0;
  for (std::uint64_t c : l.send_counts) total_send += c;
  Buffer<BodyRecord> send(total_send);
  const std::size_t n_stages = k_engine_stages.size();
  std::vector<double> times(4 * n_steps, 0), stage_times(n_stages * n_steps, 0);
  std::vector<std::uint64_t> found(n_steps, 0);
  const std::size_t mid = l.lower_ghosts;  // B's boundary owned rows start here
  for (std::size_t k = 0; k < n_steps; ++k) {
    const auto s0 = Clock::now();
    std::exception_ptr error, interior_error;
    std::uint64_t found_a = 0, found_b = 0;
    double t_interior = 0;
    std::thread interior;
    auto detect_interior = [&] {
      const auto i0 = Clock::now();
      try {
        found_a = engine.detect_resident(frame);
      } catch (...) {
        interior_error = std::current_exception();
      }
      t_interior = seconds_since(i0);
    };
    try {
      if (slabs) {
        engine.read_resident(0, l.sent, b_p.data() + mid, b_r.data() + mid);
        interior = std::thread(detect_interior);
        std::size_t w = 0;
        for (std::size_t q = 0; q < p; ++q) {
          const std::size_t from = mid + (static_cast<int>(q) < me ? 0 : l.sent - l.up);
          for (std::size_t j = from; j < from + l.send_counts[q]; ++j)
            send[w++] = BodyRecord{b_p[j], b_r[j], 0};
        }
      } else {
        detect_interior();
      }
    } catch (...) {
      error = std::current_exception();
    }
    double t_halo = 0, t_boundary = 0;
    if (slabs) {
      const Buffer<BodyRecord> got = comm.exchange(send, l.send_counts, l.recv_counts);  // every rank
      try {
        if (!error) {
          for (std::size_t g = 0; g < got.size(); ++g) {
            const std::size_t row = g < mid ? g : g + l.sent;
            b_p[row] = got[g].position;
            b_r[row] = got[g].radius;
          }
          boundary->write_resident(0, b_r.size(), b_p.data(), b_r.data());
          t_halo = seconds_since(s0);
          const auto b0 = Clock::now();
          found_b = boundary->detect_resident(frame);
          t_boundary = seconds_since(b0);
        }
      } catch (...) {
        if (!error) error = std::current_exception();
      }
    }
    if (interior.joinable()) interior.join();
    if (!error) error = interior_error;
    session.agree(error, "steps");
    times[4 * k] = t_halo;
    times[4 * k + 1] = t_interior;
    times[4 * k + 2] = t_boundary;
    times[4 * k + 3] = seconds_since(s0);
    found[k] = found_a + found_b;
    for (const StageTime& t : engine.times())
      for (std::size_t j = 0; j < n_stages; ++j)
        if (t.name == k_engine_stages[j]) stage_times[k * n_stages + j] = t.seconds;
  }
  comm.allreduce_max(times);
  comm.allreduce_max(stage_times);

  // The pairs of the last step (as global ids; CUDA: downloaded now, after the timing) hash to the
  // run's (an order-free sum), so a missed pair and a duplicate cannot cancel out in the count.
  std::uint64_t hash = 0;
  if (steps > 0) {
    auto add = [&](const Contacts<Real>& c, const std::int64_t* ids) {
      for (std::size_t k = 0; k < c.size(); ++k) {
        const std::int64_t a = ids ? ids[c.id_a[k]] : c.id_a[k], b = ids ? ids[c.id_b[k]] : c.id_b[k];
        hash += pair_hash(std::min(a, b), std::max(a, b));
      }
    };
    add(engine.resident_contacts(), slabs ? owned_id.data() : nullptr);
    if (boundary) add(boundary->resident_contacts(), b_id.data());
  }
  hash = session.sum(hash);
  for (std::size_t k = 0; k < n_steps; ++k) {
    st.contacts = session.sum(found[k]);
    local_stage(session, "steps", [&] {
      if (st.contacts != expected && me == 0)
        throw Error("resident step " + std::to_string(k) + ": " + std::to_string(st.contacts) +
                    " contacts over the ranks, the run found " + std::to_string(expected) +
                    ": internal error");
      if (k + 1 == n_steps && hash != expected_hash && me == 0)
        throw Error("resident steps: the last step's pairs differ from the run's: internal error");
    });
  }
  std::vector<double> v[4];
  for (std::size_t k = 0; k < n_steps; ++k)
    for (int j = 0; j < 4; ++j) v[j].push_back(times[4 * k + static_cast<std::size_t>(j)]);
  st.halo = median_of(v[0]);
  st.interior = median_of(v[1]);
  st.boundary = median_of(v[2]);
  st.step = median_of(v[3]);
  for (std::size_t j = 0; j < n_stages && steps > 0; ++j) {
    std::vector<double> w;
    for (std::size_t k = 0; k < n_steps; ++k) w.push_back(stage_times[k * n_stages + j]);
    const double m = median_of(w);
    if (m > 0) st.stages.push_back({k_engine_stages[j], m});
  }
  return st;
}

template <class Real>
DistributedResult<Real> run(Session& session, const std::string& path, const DistributedOptions& options) {
  constexpr Precision precision = std::is_same_v<Real, float> ? Precision::fp32 : Precision::fp64;
  const Comm comm(session);
  const int ranks = comm.size(), me = comm.rank();
  const bool full = options.engine.fields == Fields::full;
  DistributedResult<Real> result;
  result.ranks = ranks;
  std::vector<double> times(6 + k_engine_stages.size(), 0.0);  // read … merge, then detect.<stage>

  // ---- options: everything checked before the first communication -------------------------------
  std::optional<Engine<Real>> engine;
  const int threads = host_threads(options, session);
  const DefaultTeam team(threads);
  result.threads = threads;
  local_stage(session, "options", [&] {
    validate(options);
    if (path.empty()) throw UsageError("no scene file given");
    EngineOptions engine_options = options.engine;
    engine_options.threads = threads;
    engine.emplace(engine_options);
  });

  // ---- read: rows, global bounds, shared frame ----------------------------------------------------
  // Rank r's partition is rows [N·r/P, N·(r+1)/P): its bounds and sample rows (so the frame and the
  // cuts are the same in both read modes). own_rows: it reads only those; every_row: all N rows.
  const bool every_row =
      ranks > 1 && (options.read == SceneRead::every_row ||
                    (options.read == SceneRead::automatic && session.local_size() == ranks));
  result.read = every_row ? SceneRead::every_row : SceneRead::own_rows;
  auto t0 = Clock::now();
  std::uint64_t n_global = 0, first = 0, part_first = 0, part_count = 0;  // first: row of position[0]
  HostVector<Vec3<double>> position;
  HostVector<double> radius;
  BoundsRecord mine{};
  local_stage(session, "read", [&] {
    const SceneShape shape = read_scene_shape(path);
    if (shape.ellipsoids > 0) {
      throw InputError(path + ": /ellipsoids: the MPI run handles spheres only (for now)");
    }
    if (shape.spheres == 0) throw InputError(path + ": the scene has no bodies");
    n_global = shape.spheres;
    part_first = n_global * static_cast<std::uint64_t>(me) / static_cast<std::uint64_t>(ranks);
    part_count =
        n_global * static_cast<std::uint64_t>(me + 1) / static_cast<std::uint64_t>(ranks) - part_first;
    first = every_row ? 0 : part_first;
    const std::uint64_t count = every_row ? n_global : part_count;
    if (count > 0) {
      Scene rows = read_scene_rows(path, first, count);
      if (rows.sphere_position.size() != count || rows.sphere_radius.size() != count) {
        throw InputError(path + ": /spheres rows " + std::to_string(first) + "+" + std::to_string(count) +
                         ": read " + std::to_string(rows.sphere_radius.size()) + " rows");
      }
      position = std::move(rows.sphere_position);
      radius = std::move(rows.sphere_radius);
    }
    if (part_count > 0) {
      // Bounds (and validation) without an id array: the reader has validated every row already, so
      // compute_bounds finds nothing; if it ever does, it runs again with the global ids, for its message.
      const std::span<const Vec3<double>> p(position.data() + (part_first - first), part_count);
      const std::span<const double> r(radius.data() + (part_first - first), part_count);
      Bounds b;
      try {
        b = compute_bounds(BodiesView{p, r, {}, {}});
      } catch (const InputError&) {
        std::vector<std::int64_t> id(part_count);
        std::iota(id.begin(), id.end(), static_cast<std::int64_t>(part_first));
        b = compute_bounds(BodiesView{p, r, id, {}});
      }
      mine = {b.lo, b.hi, b.r_max, part_count, {b.r_sum[0], b.r_sum[1], b.r_sum[2]}};
    }
  });
  Bounds global;
  {
    bool any = false;
    for (const BoundsRecord& r : comm.allgather(mine)) {
      if (r.count == 0) continue;
      Bounds b;
      b.lo = r.lo;
      b.hi = r.hi;
      b.r_max = r.r_max;
      b.count = r.count;
      for (int k = 0; k < 3; ++k) b.r_sum[k] = r.r_sum[k];
      if (any) {
        global.merge(b);
      } else {
        global = b;
        any = true;
      }
    }
  }
  Frame frame;
  int axis = 0;
  double width = 0;
  local_stage(session, "frame", [&] {
    frame = make_frame(global, options.engine.cell_size, precision, options.engine.cell_choice);
    axis = choose_axis(global, options.axis);
    double extent = 0;
    for (int k = 0; k < 3; ++k) {
      double o = component(frame.origin, k);
      extent =
          std::max({extent, std::abs(component(global.hi, k) - o), std::abs(component(global.lo, k) - o)});
    }
    width = ghost_width(global.r_max, extent, std::numeric_limits<Real>::epsilon());
  });
  result.bodies = n_global;
  result.frame = frame;
  result.cell_size = frame.cell_size;
  result.axis = axis;
  times[0] = seconds_since(t0);

  // ---- redistribute: slab cuts identical on all ranks, every body to its owner -------------------
  // One rank owns everything: no plan, no exchange, no halo, no gather, no merge; the vectors move
  // through (the engine gets the rows as read, ids 0 … N-1 implied, all pairs reported).
  const bool alone = ranks == 1;
  t0 = Clock::now();
  std::optional<SlabDecomposition> slabs;
  Buffer<BodyRecord> owned;
  EngineInput selected;  // every_row: owned and ghosts, selected from all rows
  std::uint64_t n_selected_owned = 0, n_selected_ghosts = 0;
  {
    std::vector<double> sample;
    if (options.balance == Balance::count && !alone) {
      // A regular sample by global row: every stride-th body (all of them when N <= max_sample).
      const std::uint64_t stride =
          std::max<std::uint64_t>(1, (n_global + options.max_sample - 1) / options.max_sample);
      for (std::uint64_t g = part_first + (stride - part_first % stride) % stride;
           g < part_first + part_count; g += stride) {
        sample.push_back(component(position[static_cast<std::size_t>(g - first)], axis));
      }
      sample = comm.allgatherv(sample);
    }
    Buffer<BodyRecord> send;
    std::vector<std::uint64_t> send_counts(static_cast<std::size_t>(ranks), 0);
    local_stage(session, "redistribute", [&] {
      if (options.balance == Balance::count && !alone) {
        // from_sorted_sample reads only the P-1 quantile positions floor(r·S/P): put the right order
        // statistic at each (successive selections on the remaining upper part) instead of sorting.
        const std::size_t n_s = sample.size();
        if (ranks > 64) {
          std::sort(sample.begin(), sample.end());
        } else {
          std::size_t from = 0;
          for (int r = 1; r < ranks && n_s > 0; ++r) {
            const std::size_t q = std::min<std::size_t>(
                n_s - 1,
                static_cast<std::size_t>(std::uint64_t(r) * std::uint64_t(n_s) / std::uint64_t(ranks)));
            if (q < from) continue;  // already in place (equal quantile positions)
            std::nth_element(sample.begin() + static_cast<std::ptrdiff_t>(from),
                             sample.begin() + static_cast<std::ptrdiff_t>(q), sample.end());
            from = q + 1;
          }
        }
        slabs = SlabDecomposition::from_sorted_sample(axis, sample, ranks);
      } else {
        slabs = SlabDecomposition::equal_width(axis, component(global.lo, axis), component(global.hi, axis),
                                               ranks);
      }
      if (alone) return;
      const SlabDecomposition& s = *slabs;
      if (every_row) {
        selected = select_owned_and_ghosts(position, radius, s, axis, width, me, threads, n_selected_owned,
                                           n_selected_ghosts);
        return;
      }
      send = route(
          position.size(), ranks, threads, send_counts,
          [&](std::size_t i, auto&& emit) { emit(s.owner(component(position[i], axis))); },
          [&](std::size_t i) {
            return BodyRecord{position[i], radius[i], static_cast<std::int64_t>(first + i)};
          });
    });
    if (!alone) {
      position = {};
      radius = {};
    }
    if (!alone && !every_row) {
      const std::vector<std::uint64_t> recv_counts = comm.alltoall_counts(send_counts);
      owned = comm.alltoallv(std::move(send), send_counts, recv_counts);
    }
    result.cuts = slabs->cuts();
  }
  times[1] = seconds_since(t0);

  // ---- halo: ghosts to every rank whose slab is within the ghost width ---------------------------
  t0 = Clock::now();
  Buffer<BodyRecord> ghosts;
  std::vector<std::uint64_t> ghost_recv_counts(static_cast<std::size_t>(ranks), 0);
  if (!alone && !every_row) {
    Buffer<BodyRecord> ghost_send;
    std::vector<std::uint64_t> ghost_counts(static_cast<std::size_t>(ranks), 0);
    local_stage(session, "halo", [&] {
      const SlabDecomposition& s = *slabs;
      if (!(width >= 0) || !std::isfinite(width))
        throw InputError("halo plan: ghost width is not a finite value >= 0");
      const std::size_t bad = first_bad(owned.size(), threads, [&](std::size_t i) {
        return s.owner(component(owned[i].position, axis)) != me;
      });
      if (bad < owned.size()) {
        throw InputError("halo plan: body " + std::to_string(bad) + " at " +
                         std::to_string(component(owned[bad].position, axis)) + " is not owned by rank " +
                         std::to_string(me));
      }
      ghost_send = route(
          owned.size(), ranks, threads, ghost_counts,
          [&](std::size_t i, auto&& emit) {
            s.for_each_ghost_rank(component(owned[i].position, axis), width, emit);
          },
          [&](std::size_t i) { return owned[i]; });
    });
    ghost_recv_counts = comm.alltoall_counts(ghost_counts);
    ghosts = comm.exchange(ghost_send, ghost_counts, ghost_recv_counts);
  }
  times[2] = seconds_since(t0);

  // ---- detect: owned + ghosts in id order, the owner of the smaller id reports ------------------
  t0 = Clock::now();
  Contacts<Real> local;
  local.full = full;
  const std::uint64_t n_owned = alone       ? position.size()
                                : every_row ? n_selected_owned
                                            : owned.size(),
                      n_ghosts = every_row ? n_selected_ghosts : ghosts.size();
  const bool keep = options.resident_steps > 0;  // the input stays for the resident steps
  EngineInput in;
  local_stage(session, "detect", [&] {
    if (alone) {
      local = engine->detect(BodiesView{position, radius, {}, {}}, frame);
      if (!keep) {
        position = {};
        radius = {};
      }
      return;
    }
    in = every_row ? std::move(selected) : merge_by_id(owned, ghosts, ghost_recv_counts, threads);
    owned = {};
    ghosts = {};
    if (n_owned > 0) {  // a rank that owns nothing reports nothing
      local = engine->detect(BodiesView{in.position.span(), in.radius.span(), in.id.span(), in.report.span()},
                             frame);
    }
  });
  result.backend = engine->backend();
  times[3] = seconds_since(t0);
  if (n_owned > 0) {
    // the engine's own stages, reported as "detect.<stage>" (max over ranks, like every time)
    for (const StageTime& st : engine->times())
      for (std::size_t k = 0; k < k_engine_stages.size(); ++k)
        if (st.name == k_engine_stages[k]) times[6 + k] = st.seconds;
    result.stats = engine->stats();
  }
  result.stats.entries = session.sum(result.stats.entries);
  result.stats.pair_tests = session.sum(result.stats.pair_tests);
  result.stats.key_bits = int(session.max(double(result.stats.key_bits)));

  const std::vector<std::uint64_t> owned_all = comm.allgather<std::uint64_t>(n_owned);
  result.owned_min = *std::min_element(owned_all.begin(), owned_all.end());
  result.owned_max = *std::max_element(owned_all.begin(), owned_all.end());
  result.ghosts = session.sum(n_ghosts);

  if (options.output == ContactOutput::root) {
    gather_and_merge(session, comm, local, options, threads, result, times);
  } else {
    exchange_and_merge(session, comm, local, n_global, options, threads, result, times);
  }
  result.contacts.full = full;

  if (keep) {
    const std::span<const Vec3<double>> p =
        alone ? std::span<const Vec3<double>>(position) : in.position.span();
    const std::span<const double> r = alone ? std::span<const double>(radius) : in.radius.span();
    const std::span<const std::uint8_t> report = alone ? std::span<const std::uint8_t>() : in.report.span();
    const std::span<const std::int64_t> id = alone ? std::span<const std::int64_t>() : in.id.span();
    std::uint64_t hash = 0;
    for (std::size_t k = 0; k < result.contacts.size(); ++k)
      hash += pair_hash(result.contacts.id_a[k], result.contacts.id_b[k]);
    result.steps =
        resident_steps(session, comm, *engine, frame, alone ? nullptr : &*slabs, axis, width, p, r, id,
                       report, options.resident_steps, result.total_contacts, session.sum(hash), threads);
  }

  comm.allreduce_max(times);
  const char* names[6] = {
      "read", "redistribute", "halo", "detect", options.output == ContactOutput::root ? "gather" : "exchange",
      "merge"};
  for (int s = 0; s < 6; ++s) {
    result.times.push_back({names[s], times[static_cast<std::size_t>(s)]});
    if (s == 3)
      for (std::size_t k = 0; k < k_engine_stages.size(); ++k)
        if (times[6 + k] > 0)
          result.times.push_back({std::string("detect.") + k_engine_stages[k], times[6 + k]});
  }
  return result;
}

}  // namespace

template <class Real>
DistributedResult<Real> distributed_detect(Session& session, const std::string& scene_path,
                                           const DistributedOptions& options) {
  try {
    return run<Real>(session, scene_path, options);
  } catch (const CommFailure& e) {
    // Other ranks may be waiting in a collective this rank will never join.
    session.abort(e.exit_code(), e.what());
  }
}

template DistributedResult<float> distributed_detect<float>(Session&, const std::string&,
                                                            const DistributedOptions&);
template DistributedResult<double> distributed_detect<double>(Session&, const std::string&,
                                                              const DistributedOptions&);

}  // namespace cg
