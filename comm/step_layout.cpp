// The step loop's layout (resident_steps.hpp: lay_out), at the setup and every rebuild: the skin, engine
// A's rows and its mark, the plan of the rows near the slab's cuts (interior, boundary, the halo), the
// ghosts' records exchanged, and engine B's rows (boundary rows and ghosts, ascending id) in storage
// kept across layouts. CONTACTGRID_STEP_TRACE=1 prints its parts (step_state.hpp: Trace).
#include "resident_steps.hpp"
#include "step_state.hpp"

namespace cg {

template <class Real>
void StepLoop<Real>::lay_out() {
  State& s = *m;
  const auto t0 = WallClock::now();
  const double waited = s.t[static_cast<std::size_t>(StepStage::merge_wait)];  // (a join below: rebuild's)
  s.trace.start();
  const bool first = s.layouts == 0;
  // Scenes with ellipsoids: the shape rows go into A and B (the ghosts' with the exchange). Agreed
  // over the ranks, as a rank without rows has none.
  if (first) {
    s.shapes = s.session.sum(std::uint64_t(s.bodies.shapes.empty() ? 0 : 1)) > 0;
    s.refresh = s.shapes && s.motion.refresh_shapes;
    s.grow = s.refresh && s.motion.send_semi_axes;
  }
  if (s.skin_auto) {
    s.tuner.set_length(s.global.r_max);
    s.skin = s.tuner.skin();
  }
  const int me = s.session.rank();
  const bool alone = s.session.size() == 1;  // every body interior: no plan, no halo, no engine B
  const StepBodies& b = s.bodies;            // (while the migration's merge runs: the rows through s.body)
  const std::size_t n = s.held();
  Exports<BodyRecord> exports;
  Exports<ShapeRecord> shape_exports;
  agreed_stage(s.session, "steps", [&] {
    s.a.set_skin(s.skin);
    if (s.rows_changed || !s.written || !s.device_scan) s.finish_merge();  // the rows read whole below
    s.trace.mark("merge");
    if (s.rows_changed) {  // other rows (the setup, a migration that changed this rank's): all of them
      s.a.set_resident(
          BodiesView{b.position, b.radius, {}, {}, b.shapes.shape, b.shapes.semi_axes, b.shapes.orientation});
      s.rows_changed = false;
      s.uploaded = !first;  // the setup's rows are the file's: step 1 commits its motion
    } else {                // the same rows (update_frame wrote their motion): the next detection builds
      if (!s.written) s.a.write_resident(0, b.size(), b.position.data(), b.radius.data());
      s.written = true;
      s.a.rebuild_candidates();
    }
    s.a.mark_resident();  // the rebuild check's reference: the centres of this layout
    s.trace.mark("rows");
    if (!alone) {
      // the ghost width of the layout: the frame's, over coordinates that may still grow by the
      // layout's skin, plus that skin (each of two bodies moves by at most half of it before the next
      // layout); per body (the run's GhostRule with the skin in its margin) or one for all
      const double epsilon = std::numeric_limits<Real>::epsilon();
      const double reach = s.layout_skin();
      if (s.motion.ghosts_by_radius)
        s.rule = ghost_rule(s.global, frame_extent(s.global, s.frame.origin), epsilon, reach);
      else
        s.rule = GhostRule::uniform(frame_ghost_width(s.global, s.frame.origin, epsilon, reach) + reach);
      if (s.device_scan) {
        // engine A holds the bodies' rows: the rows outside the slab's interior band are listed where
        // the rows are, and the plan classifies those alone (make_step_plan_of: the same plan)
        const Band band = interior_band(s.slabs, me, s.rule.max_width(s.global.r_max));
        const std::vector<std::size_t> rows = s.a.rows_outside(s.slabs.axis(), band.lo, band.hi);
        s.trace.mark("scan");
        std::vector<double> x(rows.size()), r(rows.size());
        const std::size_t count = rows.size();
#pragma omp parallel for num_threads(s.team()) schedule(static) if (count > (std::size_t(1) << 14))
        for (std::size_t k = 0; k < count; ++k) {
          const auto [from, i] = s.body(rows[k]);
          x[k] = component(from->position[i], s.slabs.axis());
          r[k] = from->radius[i];
        }
        s.trace.mark("plan_rows");
        s.plan = make_step_plan_of(s.slabs, me, n, rows, x, r, s.rule, s.team(), std::move(s.plan));
      } else if (s.motion.ghosts_by_radius) {
        s.plan = make_step_plan(s.slabs, me, s.coordinates(), b.radius, s.rule, s.threads);
      } else {
        s.plan = make_step_plan(s.slabs, me, s.coordinates(), s.rule.narrow_reach, s.threads);
      }
      if (s.plan.owned != n) {
        const std::size_t k = static_cast<std::size_t>(
            std::find(s.plan.role.begin(), s.plan.role.end(), RowRole::ghost) - s.plan.role.begin());
        const auto [from, i] = s.body(k);
        throw InputError("steps: body " + std::to_string(from->id[i]) + " is not owned by rank " +
                         std::to_string(me));
      }
      s.trace.mark("plan");
      s.send_counts = s.plan.halo.counts();
      exports.offsets = s.plan.halo.offsets;
      exports.rows = HostVector<BodyRecord>(s.plan.halo.total());
      if (s.shapes) {
        shape_exports.offsets = s.plan.halo.offsets;
        shape_exports.rows = HostVector<ShapeRecord>(s.plan.halo.total());
      }
      const std::size_t exported = s.plan.halo.total();
#pragma omp parallel for num_threads(s.team()) schedule(static) if (exported > (std::size_t(1) << 14))
      for (std::size_t w = 0; w < exported; ++w) {
        const auto [from, k] = s.body(s.plan.halo.rows[w]);
        exports.rows[w] = BodyRecord{from->position[k], from->radius[k], from->id[k]};
        if (s.shapes)
          shape_exports.rows[w] =
              ShapeRecord{from->shapes.orientation[k], from->shapes.semi_axes[k], from->shapes.shape[k]};
      }
      s.trace.mark("exports");
    }
  });
  s.trace.mark("agree");
  if (!alone) {
    s.recv_counts = s.comm.alltoall_counts(s.send_counts);
    // the exchange carries the ghosts' records (ids too); the steps refresh their rows
    const HostVector<BodyRecord> ghosts = s.comm.exchange(exports.rows, s.send_counts, s.recv_counts);
    HostVector<ShapeRecord> ghost_shapes;  // the same ghosts' shape rows, in the same order
    if (s.shapes) ghost_shapes = s.comm.exchange(shape_exports.rows, s.send_counts, s.recv_counts);
    s.trace.mark("exchange");
    agreed_stage(s.session, "steps", [&] { s.make_engine_b(ghosts, ghost_shapes); });
    s.trace.mark("agree_b");
    s.halo_rows = ghosts.size();
  }
  s.trace.print(me, s.layouts, "layout");
  s.steps_since_layout = 0;
  ++s.layouts;
  if (first) {
    s.setup = seconds_since(t0);
  } else {
    s.t[static_cast<std::size_t>(StepStage::rebuild)] += seconds_since(t0);
    s.relaid_now = true;
  }
  s.t[static_cast<std::size_t>(StepStage::merge_wait)] = waited;
}

template <class Real>
void StepLoop<Real>::State::make_engine_b(const HostVector<BodyRecord>& ghosts,
                                          const HostVector<ShapeRecord>& ghost_shapes) {
  b_active = false;
  const StepBodies& o = bodies;
  // the owned rows a wide ghost may touch join the boundary rows (they anchor those pairs)
  std::vector<double> wide_x, wide_r;
  for (const BodyRecord& g : ghosts)
    if (rule.wide(g.radius)) {
      wide_x.push_back(component(g.position, slabs.axis()));
      wide_r.push_back(g.radius);
    }
  if (!wide_x.empty()) {  // (every row's coordinate: the migration's merge joined first)
    finish_merge();
    add_wide_partners(plan, coordinates(), o.radius, wide_x, wide_r, rule, threads);
  }
  trace.mark("wide");
  const std::size_t nb = plan.boundary.size();
  std::vector<std::int64_t> boundary_ids(nb), ghost_ids(ghosts.size());
  const std::size_t ng = ghosts.size();
  const bool parallel = nb + ng > (std::size_t(1) << 14);
#pragma omp parallel num_threads(team()) if (parallel)
  {
#pragma omp for schedule(static) nowait
    for (std::size_t k = 0; k < nb; ++k) {
      const auto [from, i] = body(plan.boundary[k]);
      boundary_ids[k] = from->id[i];
    }
#pragma omp for schedule(static)
    for (std::size_t g = 0; g < ng; ++g) ghost_ids[g] = ghosts[g].id;
  }
  trace.mark("ids");
  rows = merge_boundary_rows(boundary_ids, ghost_ids, team());
  trace.mark("merge_rows");
  halo_lists = device_halo && !grow;
  if (halo_lists) {  // engine A's rows are this layout's: the rows it sends, its boundary rows
    a.set_row_list(kHaloList, plan.halo.rows);
    a.set_row_list(kBoundaryList, plan.boundary);
  }
  trace.mark("lists_a");
  if (nb == 0) return;  // no boundary row: the ghosts touch none of this rank's bodies
  const std::size_t total = rows.size();
  // the rows a step writes stay page-locked; the others are uploaded once a layout
  resize_kept(b_p, total, &pin_p);
  resize_kept(b_r, total, &pin_r);
  resize_kept(b_id, total, nullptr);
  resize_kept(b_mask, total, nullptr);
  resize_kept(b_shape, shapes ? total : 0, nullptr);
  resize_kept(b_semi, shapes ? total : 0, grow ? &pin_semi : nullptr);
  resize_kept(b_q, shapes ? total : 0, refresh ? &pin_q : nullptr);
  trace.mark("resize");
#pragma omp parallel for num_threads(team()) schedule(static) if (parallel)
  for (std::size_t k = 0; k < nb; ++k) {
    const auto [from, i] = this->body(plan.boundary[k]);
    const std::size_t row = rows.of_boundary[k];
    b_p[row] = from->position[i];
    b_r[row] = from->radius[i];
    b_id[row] = from->id[i];
    // A pairs the boundary rows with each other; a pair of a wide and a narrow body is its narrow one's
    b_mask[row] = kReportedBit | kPairedBit | rule.wide_bit(from->radius[i]);
    if (shapes) {
      b_shape[row] = from->shapes.shape[i];
      b_semi[row] = from->shapes.semi_axes[i];
      b_q[row] = from->shapes.orientation[i];
    }
  }
#pragma omp parallel for num_threads(team()) schedule(static) if (parallel)
  for (std::size_t g = 0; g < ng; ++g) {
    const std::size_t row = rows.of_ghost[g];
    b_p[row] = ghosts[g].position;
    b_r[row] = ghosts[g].radius;
    b_id[row] = ghosts[g].id;
    b_mask[row] = rule.wide_bit(ghosts[g].radius);
    if (shapes) {
      b_shape[row] = ghost_shapes[g].shape;
      b_semi[row] = ghost_shapes[g].semi_axes;
      b_q[row] = ghost_shapes[g].orientation;
    }
  }
  trace.mark("fill");
  if (!b) {  // kept across layouts: its workspace stays allocated
    EngineOptions ob = a.options();
    ob.high_priority = boundary_first;
    b.emplace(ob);
  }
  b->set_skin(skin);
  b->set_resident(BodiesView{b_p, b_r, {}, b_mask, b_shape, b_semi, b_q});
  if (halo_lists) {  // B's rows of the ghosts in the order they arrive, and of the boundary rows
    b->set_row_list(kHaloList, rows.of_ghost);
    b->set_row_list(kBoundaryList, rows.of_boundary);
  }
  trace.mark("b_rows");
  b_active = true;
}

template void StepLoop<float>::lay_out();
template void StepLoop<double>::lay_out();
template void StepLoop<float>::State::make_engine_b(const HostVector<BodyRecord>&,
                                                    const HostVector<ShapeRecord>&);
template void StepLoop<double>::State::make_engine_b(const HostVector<BodyRecord>&,
                                                     const HostVector<ShapeRecord>&);

}  // namespace cg
