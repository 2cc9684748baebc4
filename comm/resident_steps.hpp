#pragma once
// Resident steps (--steps, after the run): what a simulation that keeps its bodies on the GPUs pays
// per step for the same decomposition. g++-safe public header.
//
// Each rank keeps its owned bodies in its engine (A: Engine::set_resident, its GPU), ordered
// [sent down only][sent both ways][sent up only][interior], so that every halo message is one
// contiguous range, and a second engine (B) holds [ghosts from lower ranks][the boundary owned bodies
// (those sent anywhere)][ghosts from higher ranks]. A step: the boundary rows come out of A (device →
// host); A detects all pairs of the owned bodies on a second thread while this thread exchanges the
// halo (host-staged: Debian's Open MPI is not CUDA-aware) and writes B's rows (host → device); then B
// detects its pairs with the report mask "first of the pair in (owner rank, row) order is owned" and
// kPairedBit on the boundary owned bodies (their mutual pairs are A's). An interior body is farther
// than the ghost width from every other slab, so it touches no ghost: A + B find every contact of the
// rank exactly once. Every step checks that the contacts summed over ranks equal K, and the last
// step's pairs the run's (an order-free hash; CUDA: downloaded after the timing). A rank sends its
// whole downward set to every lower rank that needs any of it (upward likewise): with slabs thinner
// than the ghost width a superset of the ghosts, which changes no contact. Bodies do not move between
// steps (no migration), so a step is the "everything recomputed, halo refreshed" cost; contacts stay
// where they were computed. One rank has no halo and no engine B.
//
// Scenes with ellipsoids: A and B hold the shape rows too (the ghosts' travel with the first
// exchange), and every step refreshes the orientations as it does the positions: the boundary rows'
// quaternions come out of A (read_resident_shapes), go to the neighbours in the same message as the
// position and radius (64 bytes a row instead of 40; a second message per neighbour measured slower,
// BENCHMARKS §10) and into B's rows (write_resident_shapes), inside the halo time, so the step costs
// what a simulation that rotates its bodies pays. Sphere-only scenes send and call nothing more.
// Semi-axes stay fixed (set once); a simulation whose shapes grow sets StepMotion::send_semi_axes:
// they then go out of A and into B with the orientations, in a message of their own.
// StepMotion::spin makes the steps rotate the ellipsoids (spun_orientation, written into A on the
// owning rank before the step's clock starts, as an integrator would): the contacts then change
// from step to step, so instead of the file's K the last step's contacts (count and pair hash,
// summed over ranks) are checked against a detection from scratch of the turned bodies: each rank
// detects its file-run rows (owned + ghosts) with every orientation computed by the rule from the
// body's id, never received, so a stale ghost orientation in B makes the two differ.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "assemble.hpp"
#include "engine.hpp"
#include "session.hpp"
#include "slab_decomposition.hpp"

namespace cg {

// How the bodies change between the steps. Default: not at all (the file's contacts every step).
struct StepMotion {
  // Radians per step: at step s (1 … N) every ellipsoid's orientation is spun_orientation(id, q0,
  // spin·s); spheres do not turn. 0: the bodies keep the file's orientations.
  double spin = 0;
  // The ghosts' semi-axes travel with their orientations every step (a simulation whose shapes grow;
  // its bounding radii travel already). Here they never change: off, they go once, at setup.
  bool send_semi_axes = false;
  // Off only to show that the check catches stale ghosts (tests): B's shape rows keep the first
  // exchange's, as if the steps refreshed positions and radii alone.
  bool refresh_shapes = true;
  // Called on every rank after each step with the number of steps done (a progress line; empty: none).
  std::function<void(int)> on_step;
};

// Per step the maximum over ranks, then the median over the steps.
struct StepStats {
  int steps = 0;
  std::uint64_t contacts = 0;   // per step, summed over ranks (checked equal to the file's K; with a
                                // spin the last step's, checked equal to a detection from scratch)
  std::uint64_t hash = 0;       // the last step's pairs, pair_hash summed over ranks (checked likewise)
  double spin = 0;              // StepMotion::spin of the steps (0: the bodies did not turn)
  bool turned = false;          // the ellipsoids turned (a spin and a scene with ellipsoids)
  bool oriented = false;        // the halo carried the ghosts' orientations (a scene with ellipsoids)
  std::uint64_t halo_rows = 0;  // ghost rows refreshed per step, summed over ranks
  double setup = 0;             // layout, first exchange, upload (once, max over ranks)
  double halo = 0;              // ghost refresh: boundary rows (and orientations) out of the GPU, MPI, into B
  double interior = 0;          // the owned bodies alone (all their pairs), overlapping the halo
  double boundary = 0;          // the boundary owned bodies against the ghosts, after the halo
  double step = 0;              // wall time of a step
  StageTimes stages;            // the engine's stages of the interior detection
};

// The engine's stage names (both backends), in pipeline order ("upload": CUDA only).
const std::vector<std::string>& engine_stage_names();

// An order-free fingerprint of a contact pair; a contact set's is the sum over its pairs.
std::uint64_t pair_hash(std::int64_t a, std::int64_t b);

// The spin's rule: body `id`'s orientation `q0` turned by `angle` radians (world frame) about a unit
// axis fixed per body, uniform on the sphere as a pure function of the id (pair_hash of (id, 1) and
// (id, 2)). Any rank computes any body's orientation at any step from the id alone.
Vec3<double> spin_axis(std::int64_t id);
Quat<double> spun_orientation(std::int64_t id, Quat<double> q0, double angle);

// Collective. `in`: this rank's engine input of the run (owned + ghosts, report mask = owned);
// `expected`, `expected_hash`: the run's K and the sum over ranks of its pairs' hashes (pair_hash of
// (id_a, id_b)). A mismatch is an Error on every rank.
template <class Real>
StepStats resident_steps(Session& session, Engine<Real>& engine, const Frame& frame,
                         const SlabDecomposition& slabs, double width, const EngineInput& in, int steps,
                         const StepMotion& motion, std::uint64_t expected, std::uint64_t expected_hash,
                         int threads);

}  // namespace cg
