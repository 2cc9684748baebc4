// The step loop's rebuild of the owners (resident_steps.hpp: rebalance, migrate): the slab cuts moved
// toward the owned centres' quantiles when the owned counts drift apart, then every body whose centre
// left its slab sent to its new owner with its rows, shape rows and the caller's state. The candidates
// for leaving are the rows outside the slab's interior band, listed where engine A's rows are
// (Engine::rows_outside; CONTACTGRID_STEP_SCAN=host: every row on the host); engine A's rows change in
// place (Engine::splice_resident), and the host's rows are merged by id beside the step's detection
// that follows the layout (step_state.hpp: start_merge, finish_merge; CONTACTGRID_STEP_MERGE=layout:
// beside the layout, =wait: before it).
#include "resident_steps.hpp"
#include "step_state.hpp"

namespace cg {

template <class Real>
void StepLoop<Real>::rebalance() {
  State& s = *m;
  s.finish_merge();
  const auto t0 = WallClock::now();
  const int ranks = s.session.size();
  const std::vector<std::uint64_t> counts = allgather_counts(s.session, s.bodies.size());
  const std::uint64_t total = std::accumulate(counts.begin(), counts.end(), std::uint64_t(0));
  const std::uint64_t most = *std::max_element(counts.begin(), counts.end());
  const double mean = double(total) / ranks;
  if (ranks == 1 || total == 0 || double(most) / mean - 1 <= s.balance.threshold) {
    s.t[static_cast<std::size_t>(StepStage::migrate)] += seconds_since(t0);
    return;
  }
  // a regular sample of the owned centres (every stride-th body in rank order), on every rank
  const std::uint64_t stride =
      std::max<std::uint64_t>(1, (total + s.balance.max_sample - 1) / s.balance.max_sample);
  std::uint64_t first = 0;
  for (int r = 0; r < s.session.rank(); ++r) first += counts[static_cast<std::size_t>(r)];
  std::vector<double> sample;
  for (std::uint64_t g = first + (stride - first % stride) % stride; g < first + s.bodies.size(); g += stride)
    sample.push_back(component(s.bodies.position[static_cast<std::size_t>(g - first)], s.slabs.axis()));
  sample = allgather_values(s.session, sample);
  agreed_stage(s.session, "steps", [&] {
    const std::vector<double> target = SlabDecomposition::from_sample(s.slabs.axis(), sample, ranks).cuts();
    std::vector<double> cuts = s.slabs.cuts();
    for (std::size_t i = 0; i < cuts.size(); ++i) {
      cuts[i] += s.balance.fraction * (target[i] - cuts[i]);
      if (i > 0) cuts[i] = std::max(cuts[i], cuts[i - 1]);  // rounding keeps the order
    }
    s.slabs = SlabDecomposition(s.slabs.axis(), std::move(cuts));
  });
  ++s.rebalances;
  s.t[static_cast<std::size_t>(StepStage::migrate)] += seconds_since(t0);
}

template <class Real>
void StepLoop<Real>::migrate() {
  State& s = *m;
  if (s.session.size() == 1) return;
  s.finish_merge();
  const auto t0 = WallClock::now();
  const int me = s.session.rank();
  const std::size_t p = static_cast<std::size_t>(s.session.size()), stride = s.bodies.state_bytes;
  StepBodies& b = s.bodies;
  ExportPlan plan;  // the rows that leave, by their new owner (none to this rank)
  std::vector<std::uint64_t> send_counts(p, 0);
  HostVector<BodyRecord> send;
  HostVector<ShapeRecord> send_shapes;
  HostVector<std::byte> send_state;
  agreed_stage(s.session, "steps", [&] {
    // the owners' test of the rows that may have left: where engine A holds the bodies' rows, those
    // outside the slab's interior band, selected where the rows are (CUDA: on the device, only their
    // indices downloaded); else every row (CONTACTGRID_STEP_SCAN=host: the former pass)
    const bool scan = s.device_scan && s.layouts > 0 && !s.rows_changed && s.a.resident_size() == b.size();
    std::vector<std::size_t> rows;
    std::span<const double> x;
    if (scan) {
      const Band band = interior_band(s.slabs, me, 0);
      rows = s.a.rows_outside(s.slabs.axis(), band.lo, band.hi);
    } else {
      x = s.coordinates();
    }
    const int axis = s.slabs.axis();
    plan = route<std::size_t, std::allocator<std::size_t>>(
        scan ? rows.size() : b.size(), s.session.size(), s.threads,
        [&](std::size_t k, auto&& emit) {
          const int r = s.slabs.owner(scan ? component(b.position[rows[k]], axis) : x[k]);
          if (r != me) emit(r);
        },
        [&](std::size_t k) { return scan ? rows[k] : k; });
    for (std::size_t r = 0; r < p; ++r) send_counts[r] = plan.count(static_cast<int>(r));
  });
  const std::uint64_t leaving = std::accumulate(send_counts.begin(), send_counts.end(), std::uint64_t(0));
  const std::uint64_t moving = s.session.sum(leaving);
  if (moving == 0) {
    s.t[static_cast<std::size_t>(StepStage::migrate)] += seconds_since(t0);
    return;
  }
  agreed_stage(s.session, "steps", [&] {
    send = HostVector<BodyRecord>(leaving);
    if (s.shapes) send_shapes = HostVector<ShapeRecord>(leaving);
    send_state = HostVector<std::byte>(leaving * stride);
#pragma omp parallel for num_threads(s.threads) schedule(static) if (leaving > (std::uint64_t(1) << 14))
    for (std::size_t w = 0; w < leaving; ++w) {
      const std::size_t k = plan.rows[w];
      send[w] = BodyRecord{b.position[k], b.radius[k], b.id[k]};
      if (s.shapes)
        send_shapes[w] = ShapeRecord{b.shapes.orientation[k], b.shapes.semi_axes[k], b.shapes.shape[k]};
      std::copy_n(b.state.data() + k * stride, stride, send_state.data() + w * stride);
    }
  });
  const std::vector<std::uint64_t> recv_counts = s.comm.alltoall_counts(send_counts);
  HostVector<BodyRecord> got = s.comm.alltoallv(std::move(send), send_counts, recv_counts);
  HostVector<ShapeRecord> got_shapes;
  if (s.shapes) got_shapes = s.comm.alltoallv(std::move(send_shapes), send_counts, recv_counts);
  HostVector<std::byte> got_state;
  if (stride > 0) {
    std::vector<std::uint64_t> sb(p), rb(p);
    for (std::size_t r = 0; r < p; ++r) sb[r] = send_counts[r] * stride, rb[r] = recv_counts[r] * stride;
    got_state = s.comm.alltoallv(std::move(send_state), sb, rb);
  }
  agreed_stage(s.session, "steps", [&] {
    if (leaving == 0 && got.empty()) return;  // this rank's rows stay as they are
    // the arrivals sorted by id, the leaving rows ascending, then the rows that stay and the
    // arrivals merged by id into the spare storage (the runs between the changes copied in parallel)
    std::vector<std::size_t> order(got.size());
    std::iota(order.begin(), order.end(), std::size_t(0));
    std::sort(order.begin(), order.end(),
              [&](std::size_t x, std::size_t y) { return got[x].id < got[y].id; });
    const bool shapes = s.shapes && (!b.shapes.empty() || !got_shapes.empty());
    StepBodies arrivals = sized_step_bodies(got.size(), shapes, stride);
    for (std::size_t j = 0; j < order.size(); ++j) {
      const std::size_t g = order[j];
      arrivals.position[j] = got[g].position;
      arrivals.radius[j] = got[g].radius;
      arrivals.id[j] = got[g].id;
      if (shapes) {
        arrivals.shapes.shape[j] = got_shapes[g].shape;
        arrivals.shapes.semi_axes[j] = got_shapes[g].semi_axes;
        arrivals.shapes.orientation[j] = got_shapes[g].orientation;
      }
      std::copy_n(got_state.data() + g * stride, stride, arrivals.state.data() + j * stride);
    }
    std::vector<std::size_t> gone(plan.rows.begin(), plan.rows.end());
    std::sort(gone.begin(), gone.end());
    // engine A's rows (the moved positions of update_frame) changed the same way where they are,
    // unless the layout sets them all anyway
    const bool in_place = s.splice && s.layouts > 0 && !s.rows_changed && s.a.resident_size() == b.size();
    std::vector<std::size_t> at;
    if (in_place && s.device_scan && s.defer_merge) {
      // the host rows merged beside the layout (finish_merge joins); engine A's spliced meanwhile
      at = arrival_places(b, gone, arrivals, shapes, s.threads);
      s.merged = SpliceMap(b.size(), gone, at);
      s.arrivals = std::move(arrivals);
      s.merge_pending = true;
      s.merge_gone = gone;
      s.merge_at = at;
      s.merge_shapes = shapes;
      if (!s.merge_at_detection) s.start_merge();  // (else the step's detection starts it)
    } else {
      at = merge_step_bodies(b, gone, arrivals, shapes, s.spare, s.threads);
      std::swap(b, s.spare);
    }
    const StepBodies& come = s.merge_pending ? s.arrivals : arrivals;
    if (in_place) {
      s.a.splice_resident(gone, at,
                          BodiesView{come.position,
                                     come.radius,
                                     {},
                                     {},
                                     come.shapes.shape,
                                     come.shapes.semi_axes,
                                     come.shapes.orientation});
    } else {
      s.rows_changed = true;
    }
  });
  s.migrated += moving;
  s.t[static_cast<std::size_t>(StepStage::migrate)] += seconds_since(t0);
}

template void StepLoop<float>::rebalance();
template void StepLoop<double>::rebalance();
template void StepLoop<float>::migrate();
template void StepLoop<double>::migrate();

}  // namespace cg
