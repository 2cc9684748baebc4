// The resident steps of a `detect` run (--steps N): the step loop's sequence, the checks of a run
// whose bodies do not move or only turn, the refusal of a drift beyond the mode's range, and the last
// step's bodies as a scene file.
#include "run/steps.hpp"

#include <fmt/format.h>

#include <cmath>
#include <string>

#include "agreed_stage.hpp"
#include "host_vector.hpp"
#include "io/scene_file.hpp"
#include "resident_steps.hpp"

namespace cg {

namespace {

// The --spin check: the last step's contacts (count and pair hash, summed over ranks) against a
// detection from scratch of the turned bodies: each rank detects its run's rows (owned + ghosts)
// with every orientation computed by the spin's rule from the body's id, never received, so a stale
// ghost orientation in the steps makes the two differ. Collective; Error on every rank otherwise.
template <class Real>
void check_spin(const Session& session, const EngineOptions& engine_options, const Frame& frame,
                const EngineInput& input, const StepMotion& motion, const StepStats& steps, int threads) {
  std::uint64_t want = 0, want_hash = 0;
  agreed_stage(session, "steps", [&] {
    if (input.owned == 0) return;  // as the run: a rank without owned bodies detects nothing
    const std::size_t n = input.radius.size();
    const double angle = motion.spin * steps.steps;
    HostVector<Quat<double>> q(n);
#pragma omp parallel for num_threads(threads) schedule(static)
    for (std::size_t i = 0; i < n; ++i) {
      const std::int64_t id = input.implied() ? static_cast<std::int64_t>(i) : input.id[i];
      q[i] = input.shapes.shape[i] == Shape::ellipsoid
                 ? spun_orientation(id, input.shapes.orientation[i], angle)
                 : input.shapes.orientation[i];
    }
    EngineOptions options = engine_options;
    options.skin = 0;
    options.skin_auto = false;
    BodiesView bodies = input.view();
    bodies.orientation = q;
    const Contacts<Real> c = Engine<Real>(options).detect(bodies, frame);
    want = c.size();
    for (std::size_t j = 0; j < c.size(); ++j) want_hash += pair_hash(c.id_a[j], c.id_b[j]);
  });
  want = session.sum(want);
  want_hash = session.sum(want_hash);
  agreed_stage(session, "steps", [&] {
    if ((steps.contacts != want || steps.hash != want_hash) && session.rank() == 0)
      throw Error("resident steps: the last step's " + std::to_string(steps.contacts) +
                  " contacts over the ranks differ from a detection of the turned bodies from scratch (" +
                  std::to_string(want) + (steps.contacts == want ? ", other pairs" : "") +
                  "): a stale orientation; internal error");
  });
}

// Bodies that do not move: every step's contacts are the run's K, and the last step's pairs hash to
// the run's (an order-free sum, so a missed pair and a duplicate cannot cancel out in the count).
template <class Real>
void check_unmoved(const Session& session, const DistributedResult<Real>& result, const StepStats& steps) {
  std::uint64_t hash = 0;
  for (std::size_t k = 0; k < result.contacts.size(); ++k)
    hash += pair_hash(result.contacts.id_a[k], result.contacts.id_b[k]);
  hash = session.sum(hash);
  agreed_stage(session, "steps", [&] {
    if (session.rank() != 0) return;
    for (std::size_t k = 0; k < steps.step_contacts.size(); ++k)
      if (steps.step_contacts[k] != result.total_contacts)
        throw Error("resident step " + std::to_string(k + 1) + ": " + std::to_string(steps.step_contacts[k]) +
                    " contacts over the ranks, the run found " + std::to_string(result.total_contacts) +
                    ": internal error");
    if (steps.steps > 0 && steps.hash != hash)
      throw Error("resident steps: the last step's pairs differ from the run's: internal error");
  });
}

// The last step's bodies as a scene file (rank 0; ids: the file's, spheres first): `detect` of it
// gives the last step's contacts. Collective.
void write_final_scene(const Session& session, const StepBodies& all, std::uint64_t ellipsoids,
                       const std::string& path) {
  agreed_stage(session, "final scene", [&] {
    if (session.rank() != 0) return;
    const std::size_t n = all.size(), spheres = n - static_cast<std::size_t>(ellipsoids);
    Scene scene;
    scene.sphere_position = HostVector<Vec3<double>>(all.position.begin(), all.position.begin() + spheres);
    scene.sphere_radius = HostVector<double>(all.radius.begin(), all.radius.begin() + spheres);
    for (std::size_t k = spheres; k < n; ++k) {
      const Quat<double>& q = all.shapes.orientation[k];
      scene.ellipsoid_position.push_back(all.position[k]);
      scene.ellipsoid_semi_axes.push_back(all.shapes.semi_axes[k]);
      scene.ellipsoid_orientation.push_back({q.w, q.x, q.y, q.z});
    }
    write_scene(path, scene);
  });
}

}  // namespace

// --drift's reach against the mode's coordinate range (steps.hpp).
template <class Real>
void check_drift_range(const Session& session, const std::string& path, const Bounds& global,
                       const DistributedOptions& options) {
  const StepMotion& motion = options.step_motion;
  if (motion.drift == 0 || options.resident_steps == 0) return;
  agreed_stage(session, "steps", [&] {
    const double reach = std::abs(motion.drift) * options.resident_steps;
    Bounds b = global;
    b.lo = {b.lo.x - reach, b.lo.y - reach, b.lo.z - reach};
    b.hi = {b.hi.x + reach, b.hi.y + reach, b.hi.z + reach};
    std::string why;  // the mode's own refusal
    auto holds = [&](Precision p) {
      if (!std::isfinite(b.lo.x + b.lo.y + b.lo.z + b.hi.x + b.hi.y + b.hi.z)) {
        why = "coordinates beyond the largest double";
        return false;
      }
      try {
        const Frame f = make_frame(b, options.engine.cell_size, p, options.engine.cell_choice);
        plan_grid(b, f, p);
        return true;
      } catch (const InputError& e) {
        why = e.what();
        return false;
      }
    };
    const Precision mode = options.engine.fp32_broad_phase ? Precision::mixed : precision_of<Real>();
    if (holds(mode)) return;
    const std::string reason = why;
    std::string others;
    for (Precision p : {Precision::mixed, Precision::fp64})
      if (p != mode && holds(p)) others += std::string(others.empty() ? "" : " or ") + to_string(p);
    throw InputError(path + ": --drift " + fmt::format("{:g}", motion.drift) + " over " +
                     std::to_string(options.resident_steps) + " steps carries the bodies up to " +
                     fmt::format("{:g}", reach) +
                     " beyond the scene's bounds, out of the coordinate range of " + to_string(mode) + " (" +
                     reason + ")" +
                     (others.empty() ? "; no mode holds it: use a smaller drift or fewer steps"
                                     : "; use --precision " + others));
  });
}

// The step loop (steps.hpp); with a drift the last step's contacts for the caller to collect,
// else the checks (check_spin, check_unmoved).
template <class Real>
StepStats run_steps(Session& session, Engine<Real>& engine, const SlabDecomposition& slabs,
                    const EngineInput& input, const DistributedResult<Real>& result,
                    const DistributedOptions& options, int threads, std::optional<Contacts<Real>>& last) {
  StepMotion motion = options.step_motion;
  motion.ghosts_by_radius = true;  // the run's per-body halo (the steps' contacts are its bits)
  StepStats st;
  {
    StepLoop<Real> loop(session, engine, slabs, motion, threads);
    // the file poses carry orientations where any rank's bodies have shape rows (the same state on
    // every rank: a migration moves it)
    const bool orientations = session.sum(std::uint64_t(input.shapes.empty() ? 0 : 1)) > 0;
    agreed_stage(session, "steps", [&] {
      loop.bodies() = owned_bodies(input, threads);
      attach_file_poses(loop.bodies(), orientations, threads);
    });
    loop.update_frame(0);
    loop.lay_out();
    for (int step = 1; step <= options.resident_steps; ++step) {
      Moved moved;
      agreed_stage(session, "steps", [&] { moved = move_bodies(loop.bodies(), motion, step, threads); });
      if (moved.positions) loop.update_frame(step);
      if (moved.positions && loop.rebuild_due()) {
        loop.rebalance();
        loop.migrate();
        loop.lay_out();
      }
      loop.commit(moved);
      loop.detect_interior();
      loop.refresh_ghosts();
      loop.detect_boundary();
      loop.collect();
      if (motion.on_step) motion.on_step(step);
    }
    st = loop.stats();
    st.hash = loop.pair_hash_sum();
    if (motion.drift != 0 && options.resident_steps > 0) {
      last.emplace();
      agreed_stage(session, "steps", [&] { *last = loop.contacts(); });
    }
    if (!options.final_scene.empty())
      write_final_scene(session, loop.gather_bodies(), result.ellipsoids, options.final_scene);
  }  // engine B's memory is free for check_spin's engine
  if (motion.drift != 0) return st;
  if (st.turned)
    check_spin<Real>(session, engine.options(), result.frame, input, motion, st, threads);
  else
    check_unmoved(session, result, st);
  return st;
}

template StepStats run_steps<float>(Session&, Engine<float>&, const SlabDecomposition&, const EngineInput&,
                                    const DistributedResult<float>&, const DistributedOptions&, int,
                                    std::optional<Contacts<float>>&);
template StepStats run_steps<double>(Session&, Engine<double>&, const SlabDecomposition&, const EngineInput&,
                                     const DistributedResult<double>&, const DistributedOptions&, int,
                                     std::optional<Contacts<double>>&);
template void check_drift_range<float>(const Session&, const std::string&, const Bounds&,
                                       const DistributedOptions&);
template void check_drift_range<double>(const Session&, const std::string&, const Bounds&,
                                        const DistributedOptions&);

}  // namespace cg
