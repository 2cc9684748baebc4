// contactgrid simulate (simulate.hpp): the scene and its motion in, the run directory out.
#include "simulate/simulate.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <sstream>

#include "io/scene_file.hpp"
#include "run/progress.hpp"
#include "run/stop.hpp"
#include "session.hpp"
#include "simulate/distributed.hpp"
#include "simulate/run_output.hpp"
#include "simulate/simulate_plot.hpp"

namespace cg {

DemBodies dem_bodies_of(const Scene& s) {
  DemBodies b;
  const std::size_t n = s.sphere_count(), e = s.ellipsoid_count();
  const bool shapes = e > 0;
  for (std::size_t i = 0; i < n; ++i) {
    b.position.push_back(s.sphere_position[i]);
    b.radius.push_back(s.sphere_radius[i]);
    b.velocity.push_back(s.sphere_velocity.empty() ? Vec3<double>{0, 0, 0} : s.sphere_velocity[i]);
    b.angular_velocity.push_back(s.sphere_angular_velocity.empty() ? Vec3<double>{0, 0, 0}
                                                                   : s.sphere_angular_velocity[i]);
    if (shapes) {
      b.shape.push_back(Shape::sphere);
      b.semi_axes.push_back({s.sphere_radius[i], s.sphere_radius[i], s.sphere_radius[i]});
      b.orientation.push_back({1, 0, 0, 0});
    }
  }
  for (std::size_t j = 0; j < e; ++j) {
    const Vec3<double> a = s.ellipsoid_semi_axes[j];
    const auto& q = s.ellipsoid_orientation[j];
    const double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    b.position.push_back(s.ellipsoid_position[j]);
    b.radius.push_back(std::max({a.x, a.y, a.z}));
    b.velocity.push_back(s.ellipsoid_velocity.empty() ? Vec3<double>{0, 0, 0} : s.ellipsoid_velocity[j]);
    b.angular_velocity.push_back(s.ellipsoid_angular_velocity.empty() ? Vec3<double>{0, 0, 0}
                                                                      : s.ellipsoid_angular_velocity[j]);
    b.shape.push_back(Shape::ellipsoid);
    b.semi_axes.push_back(a);
    b.orientation.push_back({q[0] / len, q[1] / len, q[2] / len, q[3] / len});
  }
  return b;
}

namespace {

// The walls: --walls, else the scene's simulate_walls attribute (generate --kind pour), else none.
std::vector<dem::Wall> walls_of(const SimulateCommand& cmd, const Scene& scene) {
  std::vector<std::string> specs = cmd.walls;
  if (specs.empty()) {
    if (auto it = scene.attributes.find("simulate_walls"); it != scene.attributes.end()) {
      if (const auto* text = std::get_if<std::string>(&it->second)) {
        std::stringstream ss(*text);
        std::string spec;
        while (std::getline(ss, spec, ';'))
          if (!spec.empty()) specs.push_back(spec);
      }
    }
  }
  std::vector<dem::Wall> walls;
  for (const std::string& spec : specs)
    for (const dem::Wall& w : parse_wall(spec)) walls.push_back(w);
  return walls;
}

// The largest speed the run should resolve: the bodies' own, or a fall over the scene's height.
double expected_speed(const DemBodies& b, Vec3<double> g) {
  double v = 0, lo = 1e300, hi = -1e300;
  const double gl = std::sqrt(dot(g, g));
  for (std::size_t i = 0; i < b.size(); ++i) {
    v = std::max(v, std::sqrt(dot(b.velocity[i], b.velocity[i])));
    if (gl > 0) {
      const double h = -dot(b.position[i], g) / gl;
      lo = std::min(lo, h - b.radius[i]);
      hi = std::max(hi, h + b.radius[i]);
    }
  }
  if (gl > 0 && hi > lo) v = std::max(v, std::sqrt(2 * gl * (hi - lo)));
  return v;
}

template <class Real>
int simulate_as(const SimulateCommand& cmd, const Scene& scene, const DemBodies& bodies, DemOptions options,
                const TimeStepLimits& limits, const BodyOrder& order) {
  using clock_type = std::chrono::steady_clock;
  const Cadence cadence(cmd);
  RunOutput out(cmd.output, simulate_parameters(cmd, scene, options, order));
  // a run ended at once by a signal (src/run/stop.hpp) still says in its log that it did not finish;
  // a stop at a stop point (between blocks of steps) unwinds to out.fail below
  CleanupAction incomplete =
      CleanupAction::append_file(out.path("log.csv"), "# status: failed: stopped by a signal\n");
  try {
    const auto t_start = clock_type::now();
    Simulation<Real> sim(bodies, options);
    const std::size_t spheres = scene.sphere_count();
    RunInfo info = simulate_run_info(cmd, bodies.size(), precision_of<Real>(), sim.backend(), 1);
    auto since = [](clock_type::time_point t) {
      return std::chrono::duration<double>(clock_type::now() - t).count();
    };
    RunSplit split;
    split.start = since(t_start);
    auto write_frame = [&] {
      auto t = clock_type::now();
      const DemBodies state = sim.bodies();
      const Contacts<Real>* contacts = cmd.write_contacts ? &sim.contacts() : nullptr;
      split.frame_gather += since(t);
      t = clock_type::now();
      out.frame(sim.steps(), sim.time(), order.to_scene(state), spheres);
      if (contacts) {
        info.cell_size = sim.engine_stats().cell_size;
        out.contacts(sim.steps(), *contacts, info);
      }
      split.frame_write += since(t);
      ++split.frames;
    };
    auto log_row = [&](double seconds_per_step) {
      auto t = clock_type::now();
      LogRow row;
      row.step = sim.steps();
      row.time = sim.time();
      row.energy = sim.energies();
      row.contacts = sim.contact_count();
      row.rebuilds = sim.engine_stats().candidate_builds;
      row.seconds_per_step = seconds_per_step;
      split.log_sums += since(t);
      t = clock_type::now();
      out.log(row);
      split.log_write += since(t);
      ++split.log_rows;
    };
    write_frame();
    log_row(0);
    Progress progress("simulate", "steps", cmd.steps, !cmd.quiet);
    const auto t0 = clock_type::now();
    std::uint64_t done = 0;
    while (done < cmd.steps) {
      const std::uint64_t to = cadence.block_end(done);
      stop_point();
      const auto t1 = clock_type::now();
      sim.run(to - done);
      const double block = since(t1);
      split.steps += block;
      const double per_step = block / double(to - done);
      done = to;
      if (cadence.log_due(done)) log_row(per_step);
      if (cadence.frame_due(done)) write_frame();
      progress.update(done);
    }
    progress.finish();
    incomplete.release();
    out.finish();
    const double seconds = since(t0);
    split.total = since(t_start);
    if (!cmd.quiet) {
      fmt::print(
          "contactgrid simulate: {} bodies, {} steps of {:.4g} s ({:.4g} s simulated) in {:.3f} s: {:.1f} "
          "steps/s, "
          "{:.3g} body-steps/s\n",
          bodies.size(), cmd.steps, options.dt, sim.time(), seconds, double(cmd.steps) / seconds,
          double(cmd.steps) * double(bodies.size()) / seconds);
      fmt::print(
          "  backend {}, precision {}, dt auto would be {:.4g} s (Rayleigh {:.4g} s, Hertz {:.4g} s), skin "
          "{:.4g}, "
          "candidate lists built {} / reused {}\n",
          to_string(sim.backend()), to_string(precision_of<Real>()), limits.automatic, limits.rayleigh,
          limits.hertz, options.engine.skin, sim.engine_stats().candidate_builds,
          sim.engine_stats().candidate_reuses);
      std::string stages;
      for (const StageTime& t : sim.engine_times())
        stages += fmt::format(" {} {:.3f}", t.name, t.seconds * 1e3);
      fmt::print("  last step: {:.2f} contacts/body; its detection (ms):{}\n",
                 2.0 * double(sim.contact_count()) / double(std::max<std::size_t>(bodies.size(), 1)), stages);
      fmt::print("{}", stage_times_report(sim.stage_times()));
      fmt::print("{}", run_split_report(split));
      fmt::print("  -> {}/ (frame_*.h5, {}run.xdmf, log.csv)\n", cmd.output,
                 cmd.write_contacts ? "contacts_*.h5, " : "");
    }
    if (cmd.plots) {
      plot_run_log(out.path("log.csv"), out.path("energy"), cmd.quiet);
      plot_final_state(sim.bodies(), out.path("final"), cmd.quiet);
    }
  } catch (const InputError& e) {  // a body named by its id in the scene
    const std::string why = order.scene_message(e.what());
    out.fail(why);
    throw InputError(why);
  } catch (const std::exception& e) {
    out.fail(e.what());
    throw;
  }
  return 0;
}

}  // namespace

Cadence::Cadence(const SimulateCommand& cmd)
    : frames(cmd.output_every > 0 ? cmd.output_every : std::max<std::uint64_t>(1, cmd.steps / 10)),
      logs(cmd.log_every > 0 ? cmd.log_every : std::max<std::uint64_t>(1, frames / 10)),
      steps(cmd.steps) {}

std::uint64_t Cadence::block_end(std::uint64_t done) const {
  return std::min({(done / logs + 1) * logs, (done / frames + 1) * frames, steps});
}

std::string stage_times_report(const DemStageTimes& t) {
  if (t.steps == 0) return {};
  const double per = 1e3 / double(t.steps);
  double total = 0;
  std::string steps, detection;
  for (const StageTime& s : t.step) {
    steps += fmt::format(" {} {:.3f}", s.name, s.seconds * per);
    total += s.seconds * per;
  }
  double engine = 0;
  for (const StageTime& s : t.detection) {
    detection += fmt::format(" {} {:.3f}", s.name, s.seconds * per);
    engine += s.seconds * per;
  }
  std::string out =
      fmt::format("  stage times (ms a step, mean of {} steps):{} = {:.3f}\n", t.steps, steps, total);
  out += fmt::format("  the engine's stages within detect (ms a step):{} = {:.3f}\n", detection, engine);
  if (t.energy_calls > 0)
    out += fmt::format("  energies: {:.3f} ms a call ({} calls, between blocks of steps)\n",
                       t.energy_seconds * 1e3 / double(t.energy_calls), t.energy_calls);
  return out;
}

std::string run_split_report(const RunSplit& s) {
  const double logs = s.log_sums + s.log_write, frames = s.frame_gather + s.frame_write;
  return fmt::format(
      "  wall time {:.3f} s: start {:.3f}, steps {:.3f} (relayout {:.3f}), {} log rows {:.3f} (sums {:.3f}, "
      "writing {:.3f}), {} frames {:.3f} (gather {:.3f}, writing {:.3f}), other {:.3f}\n",
      s.total, s.start, s.steps, s.relayout, s.log_rows, logs, s.log_sums, s.log_write, s.frames, frames,
      s.frame_gather, s.frame_write, s.total - s.start - s.steps - logs - frames);
}

RunInfo simulate_run_info(const SimulateCommand& cmd, std::size_t bodies, Precision precision,
                          Backend backend, int ranks) {
  RunInfo info;
  info.bodies = bodies;
  info.precision = to_string(precision);
  info.backend = to_string(backend);
  info.input = cmd.input;
  info.ranks = ranks;
  return info;
}

Attributes simulate_parameters(const SimulateCommand& cmd, const Scene& scene, const DemOptions& options,
                               const BodyOrder& order) {
  Attributes parameters;
  parameters["source"] = scene.source;
  parameters["dt"] = options.dt;
  parameters["young"] = options.material.young;
  parameters["poisson"] = options.material.poisson;
  parameters["density"] = options.material.density;
  parameters["restitution"] = options.material.restitution;
  parameters["friction"] = options.material.friction;
  parameters["rolling_friction"] = options.material.rolling_friction;
  parameters["gravity_x"] = options.gravity.x;
  parameters["gravity_y"] = options.gravity.y;
  parameters["gravity_z"] = options.gravity.z;
  parameters["integrator"] = std::string(options.synchronized ? "synchronized-verlet" : "verlet");
  parameters["body_order"] = order.name();
  parameters["software_version"] = std::string(CONTACTGRID_VERSION);
  std::string walls;
  for (const std::string& w : cmd.walls) walls += (walls.empty() ? "" : ";") + w;
  if (walls.empty())
    if (auto it = scene.attributes.find("simulate_walls"); it != scene.attributes.end())
      if (const auto* t = std::get_if<std::string>(&it->second)) walls = *t;
  parameters["simulate_walls"] = walls;  // a frame continues the run with its walls

  return parameters;
}

int run_simulate(const SimulateCommand& cmd, Session& session) {
  if (cmd.precision == Precision::mixed) throw UsageError("simulate: --precision is fp32 or fp64");
  const Scene scene = read_scene(cmd.input);
  DemBodies bodies = dem_bodies_of(scene);
  DemOptions options;
  options.material = cmd.material;
  options.gravity = cmd.gravity;
  options.walls = walls_of(cmd, scene);
  options.synchronized = cmd.synchronized;
  options.stage_times = cmd.stage_times;
  options.engine.backend = cmd.backend;
  options.engine.threads = cmd.threads;
  // under mpirun, each rank of a node on its own GPU (as detect's ranks)
  if (cmd.backend != Backend::cpu && session.uses_mpi())
    options.engine.device = session.device_for(cuda_device_count());
  double r_min = 1e300;
  for (std::size_t i = 0; i < bodies.size(); ++i)
    r_min = std::min(r_min,
                     bodies.shape.empty() || bodies.shape[i] == Shape::sphere
                         ? bodies.radius[i]
                         : std::min({bodies.semi_axes[i].x, bodies.semi_axes[i].y, bodies.semi_axes[i].z}));
  // skin auto: a tenth of the smallest radius (the engine rebuilds when the motion passes half of it)
  options.engine.skin = cmd.skin ? *cmd.skin : 0.1 * r_min;
  const TimeStepLimits limits = time_step_limits(bodies, cmd.material, expected_speed(bodies, cmd.gravity));
  if (cmd.dt) {
    options.dt = *cmd.dt;
    if (*cmd.dt > limits.rayleigh)
      throw UsageError(
          fmt::format("--dt {} exceeds the Rayleigh time {:.4g} s of the smallest body: refused (auto "
                      "would take {:.4g} s)",
                      *cmd.dt, limits.rayleigh, limits.automatic));
    if (*cmd.dt > 2 * limits.automatic)
      fmt::print(stderr,
                 "contactgrid simulate: warning: --dt {} is more than twice what auto takes ({:.4g} s: 0.2 x "
                 "Rayleigh "
                 "{:.4g} s, Hertz contact time {:.4g} s / 40); contacts may be under-resolved\n",
                 *cmd.dt, limits.automatic, limits.rayleigh, limits.hertz);
  } else {
    options.dt = limits.automatic;
  }
  check_dem_setup(bodies, options);  // (in the scene's order: its messages name the scene's ids)
  const BodyOrder order = simulate_order(cmd, bodies, scene.sphere_count());
  bodies = order.to_run(bodies);
  // under mpirun (any rank count, -np 1 too): the slabs of the step loop (distributed.hpp)
  if (session.uses_mpi())
    return run_simulate_distributed(cmd, session, scene, bodies, options, limits, order);
  if (cmd.precision == Precision::fp32) return simulate_as<float>(cmd, scene, bodies, options, limits, order);
  return simulate_as<double>(cmd, scene, bodies, options, limits, order);
}

BodyOrder simulate_order(const SimulateCommand& cmd, const DemBodies& bodies, std::size_t spheres) {
  using Order = SimulateCommand::Order;
  if (cmd.order == Order::cells && cmd.write_contacts)
    throw UsageError(
        "--order cells: not with --write-contacts (contact files keep the scene's ids and rows: --order "
        "file)");
  if (cmd.order == Order::file || (cmd.order == Order::automatic && cmd.write_contacts)) return {};
  return BodyOrder::cells(bodies, spheres);
}

}  // namespace cg
