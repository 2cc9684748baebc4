#pragma once
// contactgrid simulate: granular dynamics of a scene file on the engine (kernels/dem.hpp), written to a
// run directory (docs/FORMAT.md §6: run_output.hpp). Under mpirun: the slabs of the step loop
// (distributed.hpp), the same frames for any rank count.
//
//   read scene (with §5 motion) → walls, material, time step (auto: time_step_limits) → Simulation
//   → every --output-every steps a frame (and contacts), every --log-every a log row → complete
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "dem.hpp"
#include "engine.hpp"
#include "scene/scene.hpp"
#include "simulate/body_order.hpp"

namespace cg {

class Session;

struct SimulateCommand {
  std::string input, output;  // scene file, run directory
  std::uint64_t steps = 1000;
  std::optional<double> dt;                       // absent: auto
  std::uint64_t output_every = 0, log_every = 0;  // 0: steps / 10 frames, 10 log rows per frame
  Vec3<double> gravity{0, 0, -9.81};
  std::vector<std::string> walls;  // --walls specs (parse_wall)
  dem::Material material;
  bool write_contacts = false;
  Backend backend = Backend::automatic;
  Precision precision = Precision::fp64;
  std::optional<double> skin;  // absent: auto
  int threads = 0;
  bool synchronized = true;
  bool quiet = false;
  bool plots = true;         // gnuplot PNG/SVG of the log at the end, when gnuplot is present
  bool stage_times = false;  // --stage-times: where a step's time goes (DemOptions::stage_times)
  // --order: the bodies' order in the run (body_order.hpp); automatic: cells, unless the run writes
  // contact files (their rows and history stay in the scene's ids)
  enum class Order { automatic, cells, file } order = Order::automatic;
};

// The --stage-times lines: the mean milliseconds a step of each stage, and of the engine's stages
// within detect (empty when nothing was timed).
std::string stage_times_report(const DemStageTimes& t);

// Where a run's wall time went (the summary's "wall time" line), from the making of its state: the
// start (the layout, the upload, the first forces), the blocks of steps (of which the relayouts:
// under mpirun, the bodies moved between ranks), the log rows and the frames, the first included (of
// each: the sums or the gather over the ranks with the downloads, then the writing), and the rest.
struct RunSplit {
  double total = 0, start = 0, steps = 0, relayout = 0;
  double log_sums = 0, log_write = 0, frame_gather = 0, frame_write = 0;
  std::uint64_t log_rows = 0, frames = 0;
};
std::string run_split_report(const RunSplit& s);

// One --walls spec into walls (UsageError naming it):
//   plane:PX,PY,PZ,NX,NY,NZ            a plane through P, normal N (into the domain; normalised)
//   box:X0,Y0,Z0,X1,Y1,Z1              the six faces of an axis-aligned box, inside
//   open-box:X0,Y0,Z0,X1,Y1,Z1         its four sides only (x and y): open top and bottom
//   cylinder:CX,CY,R                   the inside of a vertical cylinder of radius R, axis (CX, CY)
//   orifice:CX,CY,Z,H                  a horizontal plate at height Z with a hole of radius H at (CX, CY)
//   hopper:CX,CY,R,Z,H                 cylinder + orifice: a cylinder of radius R on a plate at Z with a
//                                      central hole of radius H
std::vector<dem::Wall> parse_wall(const std::string& spec);

int run_simulate(const SimulateCommand& cmd, Session& session);

// The scene's bodies in id order (spheres, then ellipsoids) with their motion.
DemBodies dem_bodies_of(const Scene& scene);

// The run's body order from --order (UsageError: cells with contact files).
BodyOrder simulate_order(const SimulateCommand& cmd, const DemBodies& bodies, std::size_t spheres);

// When a run writes: a frame every `frames` steps, a log row every `logs` (--output-every,
// --log-every, or their defaults), over `steps` steps; the one-rank and the mpirun loops step in blocks
// that end at the next of them.
struct Cadence {
  std::uint64_t frames = 1, logs = 1, steps = 0;
  explicit Cadence(const SimulateCommand& cmd);
  std::uint64_t block_end(std::uint64_t done) const;  // the step the block after `done` ends at
  bool frame_due(std::uint64_t step) const { return step % frames == 0 || step == steps; }
  bool log_due(std::uint64_t step) const { return step % logs == 0 || step == steps; }
};

}  // namespace cg
