#pragma once
// contactgrid simulate under mpirun: the bodies in slabs as `detect --steps` holds them
// (comm/resident_steps: StepLoop), each rank integrating the bodies it owns.
//
//   kick_drift (owned) → update_frame → rebuild? (rebalance, the history rows of departing bodies to
//   their new owners, migrate with the bodies' state, lay_out) : commit → detect (A, halo, B)
//   → the ghosts' state (velocity, spin, force of the last step: the halo's rows) → step_history on
//   this rank's contacts (those whose id_a it owns) → contact_terms → the terms of pairs whose B is a
//   ghost to B's owner → body_terms (owned) → kick (owned)
//
// Each contact is computed once, by the owner of its smaller id, from both bodies' states; each body
// sums its terms in the one-rank order (its rows as A by the other id, then as B by the other id,
// walls, gravity: core/dem_step.hpp), so the trajectories are the same bits for any rank count. A
// contact's tangential spring stays with the owner of its smaller id and moves with that body. Frames,
// contacts and log.csv are written by rank 0 from what the ranks gather to it (energies summed there
// in the one-rank order of core/dem_sum.hpp).
#include "dem.hpp"
#include "io/contact_file.hpp"
#include "scene/scene.hpp"
#include "simulate/simulate.hpp"

namespace cg {

// The parameters every frame of a run carries (its root attributes).
Attributes simulate_parameters(const SimulateCommand& cmd, const Scene& scene, const DemOptions& options,
                               const BodyOrder& order);

// What a run's contact files say about the run (the cell size: set per file).
RunInfo simulate_run_info(const SimulateCommand& cmd, std::size_t bodies, Precision precision,
                          Backend backend, int ranks);

// The run of `cmd` over the session's ranks (collective; rank 0 writes the run directory).
int run_simulate_distributed(const SimulateCommand& cmd, Session& session, const Scene& scene,
                             const DemBodies& bodies, const DemOptions& options, const TimeStepLimits& limits,
                             const BodyOrder& order);

}  // namespace cg
