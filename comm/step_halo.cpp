// The step loop's halo (resident_steps.hpp: refresh_ghosts): every step the boundary rows' positions
// and radii (scenes with ellipsoids: and orientations, in the same message) to the ranks that hold
// them as ghosts, and into engine B's rows.
//
// Where the rows are (the default): the layout keeps the rows' lists in the engines (step_state.hpp:
// kHaloList, kBoundaryList), so a step moves only the halo's bytes:
//   gather_halo        (before engine A detects on the interior thread) A's halo rows packed into A's
//                      page-locked gather buffer (CUDA: a device gather, one download), and B's
//                      boundary rows copied from A's where they are (CUDA: device to device)
//   refresh_on_device  the packed rows exchanged with MPI straight from and into the engines' buffers
//                      (Debian's Open MPI is not CUDA-aware: the page-locked buffers are its staging),
//                      then scattered into B's ghost rows (CUDA: one upload, a device scatter)
// CONTACTGRID_STEP_HALO=host (and semi-axes that travel every step): refresh_on_host, the former
// path: records from the bodies on the host, B's host rows written, then all of B's rows uploaded.
// Both give B the same rows, bit for bit.
#include "resident_steps.hpp"
#include "step_state.hpp"

namespace cg {

using step_detail::OrientedRecord;

namespace {
std::size_t stage(StepStage s) { return static_cast<std::size_t>(s); }
}  // namespace

template <class Real>
void StepLoop<Real>::State::gather_halo() {
  gathered = {};
  if (!halo_lists || error) return;
  const auto g0 = WallClock::now();
  try {
    gathered = a.gather_rows(kHaloList, refresh);
    if (b_active) b->copy_rows(a, kBoundaryList, kBoundaryList, refresh);
  } catch (...) {
    fail();
  }
  t[stage(StepStage::halo_pack)] = seconds_since(g0);
}

template <class Real>
void StepLoop<Real>::State::refresh_on_device() {
  const std::size_t row = Engine<Real>::packed_row_bytes(refresh);
  std::uint64_t sent = 0, received = 0;
  for (const std::uint64_t c : send_counts) sent += c;
  for (const std::uint64_t c : recv_counts) received += c;
  // every rank exchanges, whatever its error: its neighbours wait for its messages
  std::span<const std::byte> send = gathered;
  if (send.size() != sent * row) {  // an error before the gather: the message's length, any bytes
    halo_spare.assign(sent * row, std::byte{0});
    send = halo_spare;
  }
  const bool into = b_active && !error;
  std::span<std::byte> recv;
  if (into) {
    try {
      recv = b->scatter_buffer(received, refresh);
    } catch (...) {
      fail();
    }
  }
  if (recv.size() != received * row) {
    halo_spare.resize(std::max(halo_spare.size(), received * row));
    recv = {halo_spare.data(), received * row};
  }
  const auto x0 = WallClock::now();
  comm.exchange_rows_into(send.data(), recv.data(), row, send_counts, recv_counts);
  t[stage(StepStage::halo_mpi)] = seconds_since(x0);
  if (!into || error) return;
  const auto u0 = WallClock::now();
  try {
    b->scatter_rows(kHaloList, refresh);
  } catch (...) {
    fail();
  }
  t[stage(StepStage::halo_unpack)] = seconds_since(u0);
}

template <class Real>
void StepLoop<Real>::State::refresh_on_host() {
  const auto& halo = plan.halo.rows;  // (the bodies' rows read through body(): the merge may run)
  const auto& of_ghost = rows.of_ghost;
  const bool into = b_active;
  const auto p0 = WallClock::now();
  // every rank exchanges, whatever its error: its neighbours wait for its messages
  if (refresh) {
    HostVector<OrientedRecord> send(halo.size());
    for (std::size_t w = 0; w < halo.size(); ++w) {
      const auto [o, i] = body(halo[w]);
      send[w] = OrientedRecord{o->position[i], o->radius[i], o->shapes.orientation[i]};
    }
    t[stage(StepStage::halo_pack)] = seconds_since(p0);
    const auto x0 = WallClock::now();
    const HostVector<OrientedRecord> got = comm.exchange(send, send_counts, recv_counts);
    t[stage(StepStage::halo_mpi)] = seconds_since(x0);
    if (into)
      for (std::size_t g = 0; g < got.size(); ++g) {
        b_p[of_ghost[g]] = got[g].position;
        b_r[of_ghost[g]] = got[g].radius;
        b_q[of_ghost[g]] = got[g].orientation;
      }
  } else {
    HostVector<BodyRecord> send(halo.size());
    for (std::size_t w = 0; w < halo.size(); ++w) {
      const auto [o, i] = body(halo[w]);
      send[w] = BodyRecord{o->position[i], o->radius[i], 0};
    }
    t[stage(StepStage::halo_pack)] = seconds_since(p0);
    const auto x0 = WallClock::now();
    const HostVector<BodyRecord> got = comm.exchange(send, send_counts, recv_counts);
    t[stage(StepStage::halo_mpi)] = seconds_since(x0);
    if (into)
      for (std::size_t g = 0; g < got.size(); ++g) {
        b_p[of_ghost[g]] = got[g].position;
        b_r[of_ghost[g]] = got[g].radius;
      }
  }
  if (grow) {  // semi-axes that grow: a message of their own
    HostVector<Vec3<double>> send(halo.size());
    for (std::size_t w = 0; w < halo.size(); ++w) {
      const auto [o, i] = body(halo[w]);
      send[w] = o->shapes.semi_axes[i];
    }
    const HostVector<Vec3<double>> got = comm.exchange(send, send_counts, recv_counts);
    if (into)
      for (std::size_t g = 0; g < got.size(); ++g) b_semi[of_ghost[g]] = got[g];
  }
  if (into && !error) {
    const auto u0 = WallClock::now();
    try {  // the boundary rows as the caller moved them, then B's rows into B
      for (std::size_t k = 0; k < plan.boundary.size(); ++k) {
        const auto [o, i] = body(plan.boundary[k]);
        const std::size_t row = rows.of_boundary[k];
        b_p[row] = o->position[i];
        b_r[row] = o->radius[i];
        if (refresh) b_q[row] = o->shapes.orientation[i];
        if (grow) b_semi[row] = o->shapes.semi_axes[i];
      }
      b->write_resident(0, b_r.size(), b_p.data(), b_r.data());
      if (refresh) b->write_resident_shapes(0, b_q.size(), grow ? b_semi.data() : nullptr, b_q.data());
    } catch (...) {
      fail();
    }
    t[stage(StepStage::halo_unpack)] = seconds_since(u0);
  }
}

template <class Real>
void StepLoop<Real>::refresh_ghosts() {
  State& s = *m;
  if (s.session.size() == 1) return;
  const auto h0 = WallClock::now();
  if (s.halo_lists)
    s.refresh_on_device();
  else
    s.refresh_on_host();
  // the gather's time (before the interior thread) is the halo's too
  s.t[stage(StepStage::halo)] = s.t[stage(StepStage::halo_pack)] * (s.halo_lists ? 1 : 0) + seconds_since(h0);
}

template void StepLoop<float>::refresh_ghosts();
template void StepLoop<double>::refresh_ghosts();
template void StepLoop<float>::State::gather_halo();
template void StepLoop<double>::State::gather_halo();

}  // namespace cg
