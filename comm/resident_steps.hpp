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
// where they were computed. One rank has no halo and no engine B. Scenes with ellipsoids: A and B
// hold the shape rows too (the ghosts' travel with the first exchange); a step refreshes positions and
// radii only, as the bodies neither move nor rotate here (a simulation that rotates them writes the
// orientations of the same ranges: Engine::write_resident_shapes).
#include <cstdint>
#include <string>
#include <vector>

#include "assemble.hpp"
#include "engine.hpp"
#include "session.hpp"
#include "slab_decomposition.hpp"

namespace cg {

// Per step the maximum over ranks, then the median over the steps.
struct StepStats {
  int steps = 0;
  std::uint64_t contacts = 0;   // per step, summed over ranks (checked equal to the file's K)
  std::uint64_t halo_rows = 0;  // ghost rows refreshed per step, summed over ranks
  double setup = 0;             // layout, first exchange, upload (once, max over ranks)
  double halo = 0;              // ghost refresh: boundary rows out of the GPU, MPI, ghost rows into it
  double interior = 0;          // the owned bodies alone (all their pairs), overlapping the halo
  double boundary = 0;          // the boundary owned bodies against the ghosts, after the halo
  double step = 0;              // wall time of a step
  StageTimes stages;            // the engine's stages of the interior detection
};

// The engine's stage names (both backends), in pipeline order ("upload": CUDA only).
const std::vector<std::string>& engine_stage_names();

// An order-free fingerprint of a contact pair; a contact set's is the sum over its pairs.
std::uint64_t pair_hash(std::int64_t a, std::int64_t b);

// Collective. `in`: this rank's engine input of the run (owned + ghosts, report mask = owned);
// `expected`, `expected_hash`: the run's K and the sum over ranks of its pairs' hashes (pair_hash of
// (id_a, id_b)). A mismatch is an Error on every rank.
template <class Real>
StepStats resident_steps(Session& session, Engine<Real>& engine, const Frame& frame,
                         const SlabDecomposition& slabs, double width, const EngineInput& in, int steps,
                         std::uint64_t expected, std::uint64_t expected_hash, int threads);

}  // namespace cg
