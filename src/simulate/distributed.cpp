// contactgrid simulate under mpirun (distributed.hpp).
#include "simulate/distributed.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <optional>
#include <type_traits>

#include "agreed_stage.hpp"
#include "collectives.hpp"
#include "resident_steps.hpp"
#include "run/progress.hpp"
#include "run/stop.hpp"
#include "session.hpp"
#include "simulate/distributed_dem.hpp"
#include "simulate/rank_records.hpp"
#include "simulate/resident_dem.hpp"
#include "simulate/run_output.hpp"
#include "simulate/simulate_plot.hpp"

namespace cg {
namespace {

using sim::DistributedDem;

// Sim: ResidentDem<Real> (resident_dem.hpp) or DistributedDem<Real>.
template <class Real, class Sim>
int distributed_as(const SimulateCommand& cmd, Session& session, const Scene& scene, const DemBodies& bodies,
                   const DemOptions& options, const TimeStepLimits& limits, const BodyOrder& order) {
  using clock_type = std::chrono::steady_clock;
  const bool root = session.rank() == 0;
  const Cadence cadence(cmd);
  std::optional<RunOutput> out;
  // rank 0's log says that a run ended by a signal did not finish (src/run/stop.hpp)
  CleanupAction incomplete;
  agreed_stage(session, "simulate", [&] {
    if (!root) return;
    out.emplace(cmd.output, simulate_parameters(cmd, scene, options, order));
    incomplete = CleanupAction::append_file(out->path("log.csv"), "# status: failed: stopped by a signal\n");
  });
  try {
    const int threads = options.engine.threads > 0 ? options.engine.threads : omp_get_max_threads();
    const auto t_start = std::chrono::steady_clock::now();
    Sim sim = [&] {
      if constexpr (std::is_same_v<Sim, DistributedDem<Real>>)
        return Sim(session, bodies, options, threads);
      else
        return Sim(session, bodies, options);
    }();
    const std::size_t spheres = scene.sphere_count();
    RunInfo info = simulate_run_info(cmd, bodies.size(), precision_of<Real>(), sim.backend(), session.size());
    std::vector<PairKey> previous;  // the keys of the step before an output step
    auto since = [](clock_type::time_point t) {
      return std::chrono::duration<double>(clock_type::now() - t).count();
    };
    RunSplit split;  // rank 0's clock; the blocks of steps: the slowest rank's
    split.start = session.max(since(t_start));
    auto write_frame = [&] {
      auto t = clock_type::now();
      const DemBodies& all = sim.gather_bodies(bodies);
      Contacts<Real> contacts;
      if (cmd.write_contacts) contacts = sim.gather_contacts(previous);
      split.frame_gather += since(t);
      t = clock_type::now();
      agreed_stage(session, "simulate", [&] {
        if (!root) return;
        out->frame(sim.steps(), double(sim.steps()) * options.dt, order.to_scene(all), spheres);
        if (cmd.write_contacts) {
          info.cell_size = sim.cell_size();
          out->contacts(sim.steps(), contacts, info);
        }
      });
      split.frame_write += since(t);
      ++split.frames;
    };
    auto log_row = [&](double seconds_per_step) {
      auto t = clock_type::now();
      const sim::LogSums sums = sim.log_sums();
      split.log_sums += since(t);
      t = clock_type::now();
      agreed_stage(session, "simulate", [&] {
        if (!root) return;
        LogRow row;
        row.step = sim.steps();
        row.time = double(sim.steps()) * options.dt;
        row.energy = sums.energies;
        row.contacts = sums.contacts;
        row.rebuilds = sim.rebuilds();
        row.seconds_per_step = seconds_per_step;
        out->log(row);
      });
      split.log_write += since(t);
      ++split.log_rows;
    };
    write_frame();
    log_row(0);
    const double relayout_start = sim.relayout_seconds();
    Progress progress("simulate", "steps", cmd.steps, !cmd.quiet && root);
    const auto t0 = clock_type::now();
    std::uint64_t done = 0;
    while (done < cmd.steps) {
      const std::uint64_t to = cadence.block_end(done);
      const auto t1 = clock_type::now();
      const std::uint64_t from = done;
      double keys = 0;  // the keys of a contact file's step before (its frame's gather)
      while (done < to) {
        if (cmd.write_contacts && done + 1 == to && cadence.frame_due(to)) {
          const auto tk = clock_type::now();
          previous = sim.gather_keys();
          keys = since(tk);
        }
        sim.step(done + 1 < to);  // another step follows with nothing between
        ++done;
      }
      const double block = session.max(since(t1));
      split.steps += block - keys;
      split.frame_gather += keys;
      const double per_step = block / double(to - from);
      if (cadence.log_due(done)) log_row(per_step);
      if (cadence.frame_due(done)) write_frame();
      progress.update(done);
    }
    progress.finish();
    const double seconds = since(t0);
    // the final state for the plots (only when they are drawn)
    DemBodies final_bodies;
    if (cmd.plots) final_bodies = sim.gather_bodies(bodies);
    split.total = since(t_start);
    split.relayout = session.max(sim.relayout_seconds() - relayout_start);
    const StepStats loop = sim.loop_stats();
    std::string phases;  // --stage-times under the resident ranks: each rank's step phases
    if constexpr (std::is_same_v<Sim, ResidentDem<Real>>) {
      if (cmd.stage_times) {
        const auto& p = sim.phases();
        const double per = p.steps > 0 ? 1e3 / double(p.steps) : 0;
        constexpr std::size_t kFields = 9;
        const double rows = p.steps > 0 ? double(p.halo_rows) / double(p.steps) : 0;
        const double bytes = p.halo_rows > 0 ? double(p.halo_bytes) / double(p.halo_rows) : 0;
        const std::vector<double> all =
            allgather_values(session, {p.halo * per, p.frame * per, p.relayout * per, p.forces * per,
                                       p.hidden * per, double(p.steps), double(p.overlapped), rows, bytes});
        phases =
            "  step phases (ms a step, --stage-times, each rank: kick-drift + halo (overlapped steps: "
            "the records' exchange), frame, relayout, detect + forces + kick until the device finished; "
            "hidden: the halo's part the interior's forces covered on the device, waited: the rest):\n";
        for (std::size_t r = 0; r + kFields - 1 < all.size(); r += kFields)
          phases += fmt::format(
              "    rank {}: halo {:.3f} (hidden {:.3f}, waited {:.3f}), frame {:.3f}, relayout {:.3f}, "
              "forces {:.3f} ({} steps, {} overlapped; halo {:.0f} rows sent a step, {:.0f} B a row)\n",
              r / kFields, all[r], all[r + 4], all[r] - all[r + 4], all[r + 1], all[r + 2], all[r + 3],
              all[r + 5], all[r + 6], all[r + 7], all[r + 8]);
      }
    }
    agreed_stage(session, "simulate", [&] {
      if (!root) return;
      incomplete.release();
      out->finish();
      if (!cmd.quiet) {
        fmt::print(
            "contactgrid simulate: {} bodies on {} ranks, {} steps of {:.4g} s ({:.4g} s simulated) in "
            "{:.3f} "
            "s: {:.1f} steps/s, {:.3g} body-steps/s\n",
            bodies.size(), session.size(), cmd.steps, options.dt, double(cmd.steps) * options.dt, seconds,
            double(cmd.steps) / seconds, double(cmd.steps) * double(bodies.size()) / seconds);
        fmt::print(
            "  backend {}, precision {}, dt auto would be {:.4g} s, skin {:.4g}, rows rebuilt {}, bodies "
            "that "
            "changed rank {}, slab rebalances {}, owned per rank {}-{}, the ranks' bodies {}\n",
            to_string(sim.backend()), to_string(precision_of<Real>()), limits.automatic, sim.skin(),
            sim.rebuilds(), loop.migrated, loop.rebalances, loop.owned_min, loop.owned_max,
            std::is_same_v<Sim, DistributedDem<Real>> ? "on the host (CONTACTGRID_SIMULATE_RANKS=host)"
                                                      : "resident");
        fmt::print("{}", run_split_report(split));
        fmt::print("{}", phases);
        fmt::print("  -> {}/ (frame_*.h5, {}run.xdmf, log.csv)\n", cmd.output,
                   cmd.write_contacts ? "contacts_*.h5, " : "");
      }
      if (cmd.plots) {
        plot_run_log(out->path("log.csv"), out->path("energy"), cmd.quiet);
        plot_final_state(final_bodies, out->path("final"), cmd.quiet);
      }
    });
  } catch (const InputError& e) {  // a body named by its id in the scene
    const std::string why = order.scene_message(e.what());
    if (out) out->fail(why);
    throw InputError(why);
  } catch (const std::exception& e) {
    if (out) out->fail(e.what());
    throw;
  }
  return 0;
}

}  // namespace

int run_simulate_distributed(const SimulateCommand& cmd, Session& session, const Scene& scene,
                             const DemBodies& bodies, const DemOptions& options, const TimeStepLimits& limits,
                             const BodyOrder& order) {
  // CONTACTGRID_SIMULATE_RANKS=host: each rank's forces on the host (DistributedDem); else resident
  const char* knob = std::getenv("CONTACTGRID_SIMULATE_RANKS");
  const std::string path = knob ? knob : "resident";
  if (path != "resident" && path != "host")
    throw UsageError("CONTACTGRID_SIMULATE_RANKS must be resident or host (got \"" + path + "\")");
  const bool host = path == "host";
  if (cmd.precision == Precision::fp32)
    return host ? distributed_as<float, DistributedDem<float>>(cmd, session, scene, bodies, options, limits,
                                                               order)
                : distributed_as<float, ResidentDem<float>>(cmd, session, scene, bodies, options, limits,
                                                            order);
  return host ? distributed_as<double, DistributedDem<double>>(cmd, session, scene, bodies, options, limits,
                                                               order)
              : distributed_as<double, ResidentDem<double>>(cmd, session, scene, bodies, options, limits,
                                                            order);
}

}  // namespace cg
