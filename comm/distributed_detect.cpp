#include "distributed_detect.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <limits>
#include <numeric>
#include <optional>
#include <type_traits>

#include "contact_merge.hpp"
#include "hdf5_io.hpp"
#include "mpi_detail.hpp"

namespace cg {

namespace {
// The engine's stage names (both backends), in pipeline order.
const std::vector<std::string> k_engine_stages{"plan", "pack", "entries", "sort", "pairs", "order", "narrow",
                                               "download"};
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
    throw UsageError("--cell-size: must be a finite length >= 0 (0: smallest valid)");
  }
  if (e.threads < 0) throw UsageError("--threads: must be >= 0 (0: all hardware threads)");
  if (options.max_sample < 1) throw UsageError("max_sample: must be >= 1");
  if (options.max_message_bytes < 64) throw UsageError("max_message_bytes: must be >= 64");
}

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// One body in flight between ranks. General over body kinds: a global id and a bounding sphere
// (ellipsoids will add their shape here).
struct BodyRecord {
  Vec3<double> position;
  double radius;
  std::int64_t id;
};
static_assert(std::is_trivially_copyable_v<BodyRecord>);

// Bounds of one rank, as exchanged (count 0: the rank read no body and is skipped).
struct BoundsRecord {
  Vec3<double> lo, hi;
  double r_max;
  std::uint64_t count;
};
static_assert(std::is_trivially_copyable_v<BoundsRecord>);

double component(const Vec3<double>& v, int k) { return k == 0 ? v.x : (k == 1 ? v.y : v.z); }

constexpr int k_halo_tag = 7301;

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

  // `send` grouped by destination rank (send_counts), result grouped by source rank.
  template <class T>
  std::vector<T> alltoallv(const std::vector<T>& send, const std::vector<std::uint64_t>& send_counts,
                           const std::vector<std::uint64_t>& recv_counts) const {
    if (!m_s.mpi) return send;
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
    std::vector<T> recv(rt);
    detail::RecordType type(sizeof(T));
    CG_MPI(MPI_Alltoallv(send.data(), sc.data(), sd.data(), type.get(), recv.data(), rc.data(), rd.data(),
                         type.get(), m_s.comm));
    return recv;
  }

  // Point-to-point exchange (the halo): every Irecv posted, then every Isend, then one Waitall.
  // Only ranks with a non-zero count take part; this rank's own part (none for a halo) is copied.
  template <class T>
  std::vector<T> exchange(const std::vector<T>& send, const std::vector<std::uint64_t>& send_counts,
                          const std::vector<std::uint64_t>& recv_counts) const {
    const std::size_t p = send_counts.size(), me = static_cast<std::size_t>(m_s.rank);
    std::vector<std::uint64_t> sd(p + 1, 0), rd(p + 1, 0);
    for (std::size_t r = 0; r < p; ++r) {
      sd[r + 1] = sd[r] + send_counts[r];
      rd[r + 1] = rd[r] + recv_counts[r];
    }
    std::vector<T> recv(rd[p]);
    std::copy_n(send.begin() + static_cast<std::ptrdiff_t>(sd[me]), send_counts[me],
                recv.begin() + static_cast<std::ptrdiff_t>(rd[me]));
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

  // Rank 0 receives every rank's `local` (counts[r] elements on rank r, known to all ranks) as one
  // vector per rank; other ranks get an empty result. MPI_Gatherv in rounds of at most max_bytes
  // (capped to 2^31 - 1) in all, so no byte count or displacement overflows an int.
  template <class T>
  std::vector<std::vector<T>> gather_to_root(const std::vector<T>& local, const std::vector<std::uint64_t>& counts,
                                             std::uint64_t max_bytes) const {
    static_assert(std::is_trivially_copyable_v<T>);
    if (!m_s.mpi) return {local};
    const std::size_t p = counts.size();
    const bool root = m_s.rank == 0;
    std::vector<std::vector<T>> out(root ? p : 0);
    if (root) {
      for (std::size_t r = 0; r < p; ++r) out[r].reserve(counts[r]);
    }
    const std::uint64_t budget = std::min<std::uint64_t>(max_bytes, static_cast<std::uint64_t>(INT_MAX));
    const std::uint64_t chunk = std::max<std::uint64_t>(1, budget / p / sizeof(T));  // elements per rank
    const std::uint64_t most = *std::max_element(counts.begin(), counts.end());
    const std::uint64_t rounds = (most + chunk - 1) / chunk;
    std::vector<int> rc(p), rd(p);
    std::vector<T> buffer;
    for (std::uint64_t round = 0; round < rounds; ++round) {
      auto part = [&](std::size_t r) {
        std::uint64_t begin = std::min(counts[r], round * chunk);
        return std::min(counts[r], begin + chunk) - begin;
      };
      const std::uint64_t begin = std::min<std::uint64_t>(local.size(), round * chunk);
      const std::uint64_t mine = part(static_cast<std::size_t>(m_s.rank));
      std::uint64_t total = 0;
      if (root) {
        for (std::size_t r = 0; r < p; ++r) {
          rc[r] = detail::to_mpi_count(part(r) * sizeof(T), "gather byte count");
          rd[r] = detail::to_mpi_count(total * sizeof(T), "gather byte displacement");
          total += part(r);
        }
        buffer.resize(total);
      }
      CG_MPI(MPI_Gatherv(local.data() + begin, detail::to_mpi_count(mine * sizeof(T), "gather byte count"),
                         MPI_BYTE, root ? buffer.data() : nullptr, rc.data(), rd.data(), MPI_BYTE, 0,
                         m_s.comm));
      if (root) {
        for (std::size_t r = 0; r < p; ++r) {
          const T* first = buffer.data() + rd[r] / static_cast<int>(sizeof(T));
          out[r].insert(out[r].end(), first, first + part(r));
        }
      }
    }
    return out;
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
  local_stage(session, "options", [&] {
    validate(options);
    if (path.empty()) throw UsageError("no scene file given");
    engine.emplace(options.engine);
  });

  // ---- read: own contiguous row range, global bounds, shared frame --------------------------------
  auto t0 = Clock::now();
  std::uint64_t n_global = 0, first = 0;
  std::vector<Vec3<double>> position;
  std::vector<double> radius;
  std::vector<std::int64_t> id;
  BoundsRecord mine{};
  local_stage(session, "read", [&] {
    const SceneShape shape = read_scene_shape(path);
    if (shape.ellipsoids > 0) {
      throw InputError(path + ": /ellipsoids: the MPI run handles spheres only (for now)");
    }
    if (shape.spheres == 0) throw InputError(path + ": the scene has no bodies");
    n_global = shape.spheres;
    first = n_global * static_cast<std::uint64_t>(me) / static_cast<std::uint64_t>(ranks);
    const std::uint64_t last = n_global * static_cast<std::uint64_t>(me + 1) / static_cast<std::uint64_t>(ranks);
    const std::uint64_t count = last - first;
    if (count > 0) {
      Scene rows = read_scene_rows(path, first, count);
      if (rows.sphere_position.size() != count || rows.sphere_radius.size() != count) {
        throw InputError(path + ": /spheres rows " + std::to_string(first) + "+" + std::to_string(count) +
                         ": read " + std::to_string(rows.sphere_radius.size()) + " rows");
      }
      position = std::move(rows.sphere_position);
      radius = std::move(rows.sphere_radius);
      id.resize(count);
      std::iota(id.begin(), id.end(), static_cast<std::int64_t>(first));
      const Bounds b = compute_bounds(BodiesView{position, radius, id, {}});
      mine = {b.lo, b.hi, b.r_max, count};
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
    frame = make_frame(global, options.engine.cell_size, precision);
    axis = choose_axis(global, options.axis);
    double extent = 0;
    for (int k = 0; k < 3; ++k) {
      double o = component(frame.origin, k);
      extent = std::max({extent, std::abs(component(global.hi, k) - o), std::abs(component(global.lo, k) - o)});
    }
    width = ghost_width(global.r_max, extent, std::numeric_limits<Real>::epsilon());
  });
  result.bodies = n_global;
  result.frame = frame;
  result.cell_size = frame.cell_size;
  result.axis = axis;
  times[0] = seconds_since(t0);

  // ---- redistribute: slab cuts identical on all ranks, every body to its owner -------------------
  t0 = Clock::now();
  std::optional<SlabDecomposition> slabs;
  {
    std::vector<double> coordinate(position.size());
    for (std::size_t i = 0; i < position.size(); ++i) coordinate[i] = component(position[i], axis);
    std::vector<double> sample;
    if (options.balance == Balance::count && ranks > 1) {
      // A regular sample by global row: every stride-th body (all of them when N <= max_sample).
      const std::uint64_t stride = std::max<std::uint64_t>(1, (n_global + options.max_sample - 1) / options.max_sample);
      for (std::size_t i = 0; i < coordinate.size(); ++i) {
        if ((first + i) % stride == 0) sample.push_back(coordinate[i]);
      }
      sample = comm.allgatherv(sample);
    }
    ExportPlan plan;
    std::vector<BodyRecord> send;
    local_stage(session, "redistribute", [&] {
      if (options.balance == Balance::count && ranks > 1) {
        std::sort(sample.begin(), sample.end());
        slabs = SlabDecomposition::from_sorted_sample(axis, sample, ranks);
      } else {
        slabs = SlabDecomposition::equal_width(axis, component(global.lo, axis), component(global.hi, axis), ranks);
      }
      plan = make_owner_plan(*slabs, coordinate);
      send.resize(plan.total());
      for (std::size_t k = 0; k < plan.total(); ++k) {
        const std::size_t i = plan.indices[k];
        send[k] = {position[i], radius[i], id[i]};
      }
    });
    position = {};
    radius = {};
    id = {};
    std::vector<std::uint64_t> send_counts(static_cast<std::size_t>(ranks));
    for (int r = 0; r < ranks; ++r) send_counts[static_cast<std::size_t>(r)] = plan.count(r);
    const std::vector<std::uint64_t> recv_counts = comm.alltoall_counts(send_counts);
    std::vector<BodyRecord> owned = comm.alltoallv(send, send_counts, recv_counts);
    result.cuts = slabs->cuts();
    times[1] = seconds_since(t0);

    // ---- halo: ghosts to every rank whose slab is within the ghost width ---------------------------
    t0 = Clock::now();
    ExportPlan halo;
    std::vector<BodyRecord> ghost_send;
    local_stage(session, "halo", [&] {
      std::vector<double> owned_coordinate(owned.size());
      for (std::size_t i = 0; i < owned.size(); ++i) owned_coordinate[i] = component(owned[i].position, axis);
      halo = make_halo_plan(*slabs, me, owned_coordinate, width);
      ghost_send.resize(halo.total());
      for (std::size_t k = 0; k < halo.total(); ++k) ghost_send[k] = owned[halo.indices[k]];
    });
    std::vector<std::uint64_t> ghost_counts(static_cast<std::size_t>(ranks));
    for (int r = 0; r < ranks; ++r) ghost_counts[static_cast<std::size_t>(r)] = halo.count(r);
    const std::vector<std::uint64_t> ghost_recv_counts = comm.alltoall_counts(ghost_counts);
    std::vector<BodyRecord> ghosts = comm.exchange(ghost_send, ghost_counts, ghost_recv_counts);
    ghost_send = {};
    times[2] = seconds_since(t0);

    // ---- detect: owned + ghosts in id order, the owner of the smaller id reports ------------------
    t0 = Clock::now();
    Contacts<Real> local;
    local.full = full;
    const std::uint64_t n_owned = owned.size(), n_ghosts = ghosts.size();
    local_stage(session, "detect", [&] {
      const std::size_t n = owned.size() + ghosts.size();
      std::vector<std::size_t> order(n);
      std::iota(order.begin(), order.end(), std::size_t{0});
      auto record = [&](std::size_t k) -> const BodyRecord& {
        return k < owned.size() ? owned[k] : ghosts[k - owned.size()];
      };
      auto by_id = [&](std::size_t a, std::size_t b) { return record(a).id < record(b).id; };
      if (!std::is_sorted(order.begin(), order.end(), by_id)) std::sort(order.begin(), order.end(), by_id);
      std::vector<Vec3<double>> p(n);
      std::vector<double> r(n);
      std::vector<std::int64_t> ids(n);
      std::vector<std::uint8_t> report(n);
      for (std::size_t k = 0; k < n; ++k) {
        const BodyRecord& b = record(order[k]);
        p[k] = b.position;
        r[k] = b.radius;
        ids[k] = b.id;
        report[k] = order[k] < owned.size() ? 1 : 0;
        if (k > 0 && ids[k] == ids[k - 1]) {
          throw Error("body " + std::to_string(ids[k]) + " is held twice (owned and ghost): internal error");
        }
      }
      owned = {};
      ghosts = {};
      if (n_owned > 0) {  // a rank that owns nothing reports nothing
        local = engine->detect(BodiesView{p, r, ids, report}, frame);
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

    // ---- gather: each field to rank 0, in bounded rounds ---------------------------------------------
    t0 = Clock::now();
    const std::vector<std::uint64_t> counts = comm.allgather<std::uint64_t>(local.size());
    std::vector<Contacts<Real>> runs(me == 0 ? static_cast<std::size_t>(ranks) : 0);
    auto gather = [&](auto member) {
      auto parts = comm.gather_to_root(local.*member, counts, options.max_message_bytes);
      (local.*member) = {};
      for (std::size_t r = 0; r < parts.size(); ++r) runs[r].*member = std::move(parts[r]);
    };
    gather(&Contacts<Real>::id_a);
    gather(&Contacts<Real>::id_b);
    gather(&Contacts<Real>::position_on_a);
    gather(&Contacts<Real>::position_on_b);
    gather(&Contacts<Real>::normal_on_b);
    gather(&Contacts<Real>::distance);
    if (full) {
      gather(&Contacts<Real>::local_point_a);
      gather(&Contacts<Real>::local_point_b);
      gather(&Contacts<Real>::lateral_friction_dir1);
      gather(&Contacts<Real>::lateral_friction_dir2);
    }
    for (Contacts<Real>& run : runs) run.full = full;
    times[4] = seconds_since(t0);

    // ---- merge (rank 0): k-way merge of the sorted runs, duplicates removed and counted -----------
    t0 = Clock::now();
    local_stage(session, "merge", [&] {
      if (me != 0) return;
      MergedContacts<Real> merged = merge_contact_runs<Real>(runs, full);
      runs = {};
      result.contacts = std::move(merged.contacts);
      result.duplicates_removed = merged.duplicates_removed;
      const std::string line = "merge: " + std::to_string(result.contacts.size()) + " contacts from " +
                               std::to_string(ranks) + " rank(s), " + std::to_string(merged.duplicates_removed) +
                               " duplicate(s) removed (expected 0)";
      if (options.log) {
        options.log(line);
      } else if (merged.duplicates_removed > 0) {  // a warning nobody asked for must still be seen
        std::fprintf(stderr, "%swarning: %s\n", session.prefix().c_str(), line.c_str());
      }
    });
    times[5] = seconds_since(t0);
  }
  result.contacts.full = full;

  comm.allreduce_max(times);
  const char* names[6] = {"read", "redistribute", "halo", "detect", "gather", "merge"};
  for (int s = 0; s < 6; ++s) {
    result.times.push_back({names[s], times[static_cast<std::size_t>(s)]});
    if (s == 3)
      for (std::size_t k = 0; k < k_engine_stages.size(); ++k)
        if (times[6 + k] > 0) result.times.push_back({std::string("detect.") + k_engine_stages[k], times[6 + k]});
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
