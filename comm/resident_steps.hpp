#pragma once
// The resident steps (--steps, after the run): what a simulation that keeps its bodies in its engines
// pays per step for the same decomposition. g++-safe public header.
//
// The step loop is an object whose methods are the stages of a step; src/run/pipeline.cpp sequences
// them, as it sequences the stages of a run:
//
//   lay_out            the rows of the steps (setup): the plan of the held rows (decomposition/
//                      step_plan: interior, boundary, ghost, and which rank needs which boundary row,
//                      by the run's routing rules), the first exchange of the ghosts' whole records,
//                      engine A's rows (the owned bodies) and engine B's (boundary rows + ghosts)
//   (the caller moves the bodies: bodies(), then commit: the integrator's part, before the clock)
//   detect_interior    engine A, all pairs of the owned bodies, on a second thread ...
//   refresh_ghosts     ... while this thread sends every boundary row's position and bounding radius
//                      (scenes with ellipsoids: and orientation, in the same message) to the ranks
//                      that hold it as a ghost (MPI, host-staged: Debian's Open MPI is not
//                      CUDA-aware) and writes engine B's rows
//   detect_boundary    engine B (the pairs of a boundary row with a ghost: step_plan.hpp's report
//                      rule), then the wait for A; every rank agrees on the step's errors
//   collect            this step's contacts (their count over the rank's two engines) and times
// and after the steps, pair_hash_sum (the last step's pairs: CUDA downloads them now, after the
// timing) and stats (per stage, the median over the steps of the maximum over ranks).
//
// A rank holds its bodies in ascending id in both engines (the engines' contacts then come out in
// (id_a, id_b) order with the bits of a run from scratch). Scenes with ellipsoids: A and B hold the
// shape rows too, the ghosts' from the first exchange; every step refreshes the ghosts' orientations
// with their positions, in the same message (64 bytes a row instead of 40: cheaper than a second
// message per neighbour, BENCHMARKS.md §10). Semi-axes stay fixed (set once);
// StepMotion::send_semi_axes sends them every step, in a message of their own, for a simulation whose
// shapes grow. One rank (or a rank without neighbours within the ghost width) has no boundary rows and
// no engine B.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine.hpp"
#include "session.hpp"
#include "slab_decomposition.hpp"
#include "stage_names.hpp"
#include "step_bodies.hpp"

namespace cg {

// The stages of a step, as timed (this rank's seconds; StepStats: the median over the steps of the
// maximum over ranks). step: the wall time from detect_interior to the end of detect_boundary.
enum class StepStage : int { halo, interior, boundary, step };
inline constexpr int kStepStageCount = 4;
const char* to_string(StepStage stage);

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
  double setup = 0;             // lay_out: plan, first exchange, engines' rows (once, max over ranks)
  double halo = 0;              // refresh_ghosts: boundary rows (and orientations) through MPI, into B
  double interior = 0;          // the owned bodies alone (all their pairs), overlapping the halo
  double boundary = 0;          // the boundary rows against the ghosts, after the halo
  double step = 0;              // wall time of a step
  StageTimes stages;            // the engine's stages of the interior detection
};

// The steps of one rank: engine A (the run's engine), engine B, the bodies and their plan.
template <class Real>
class StepLoop {
 public:
  // `engine`: the rank's engine (A; the loop sets its resident rows); `frame`, `slabs`, `width`: the
  // run's. Every rank constructs one; the stages below are collective, in the order above.
  StepLoop(Session& session, Engine<Real>& engine, const Frame& frame, const SlabDecomposition& slabs,
           double width, const StepMotion& motion, int threads);
  ~StepLoop();
  StepLoop(const StepLoop&) = delete;
  StepLoop& operator=(const StepLoop&) = delete;

  // Collective. `bodies`: this rank's owned bodies, ascending id (InputError naming the first body that
  // this rank does not own). Times the setup.
  void lay_out(StepBodies&& bodies);

  // This rank's owned bodies, ascending id: the caller moves them between steps, then commits.
  StepBodies& bodies();
  // The caller changed the positions (and bounding radii) and/or the orientations of bodies():
  // written into engine A's rows (the integrator's part, before the step's clock).
  void commit(bool positions, bool orientations);

  void detect_interior();  // collective (with refresh_ghosts and detect_boundary: one step)
  void refresh_ghosts();
  void detect_boundary();
  void collect();  // this step's contacts (their count) and times

  // Collective, after the steps: the order-free hash of the last step's pairs summed over ranks.
  std::uint64_t pair_hash_sum();
  // Collective: per-step contacts summed over ranks (one per step) and the statistics.
  const std::vector<std::uint64_t>& contacts_per_step();
  StepStats stats();

 private:
  struct State;
  std::unique_ptr<State> m;
};

extern template class StepLoop<float>;
extern template class StepLoop<double>;

}  // namespace cg
