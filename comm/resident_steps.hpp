#pragma once
// The resident steps (--steps, after the run): a simulation's bodies kept in each rank's engines and
// detected again every step, bodies moving between ranks as they cross the slabs' cuts. g++-safe
// public header.
//
// The step loop is an object whose methods are the stages of a step; src/run/pipeline.cpp sequences
// them, as it sequences the stages of a run:
//
//   lay_out            the rows of the steps (setup, and every rebuild): the plan of the owned rows
//                      (decomposition/step_plan: interior or boundary, and which rank needs which
//                      boundary row, by the run's routing rules over the ghost width plus the skin:
//                      per body with StepMotion::ghosts_by_radius, a large body to every slab it
//                      reaches and the small ones' halos small), the exchange of the ghosts' whole
//                      records, engine A's rows (the owned bodies) and engine B's (boundary rows, the
//                      owned rows a wide ghost may touch, and the ghosts)
//   (the caller moves bodies(): the integrator's part, before the step's clock)
//   update_frame       the moved bodies' bounds over the ranks (a centre that is not finite stops the
//                      run: InputError naming the body and the step), the frame of a run from scratch
//                      of them (so the contacts are its bits), the ghost width; after the first
//                      layout the moved positions go into engine A first and the engine computes the
//                      bounds and the largest displacement since the layout where its rows are
//                      (Engine::resident_extent; CUDA: on the device, no centre read on the host)
//   rebuild_due        whether a body moved by more than half the layout's skin since the layout (the
//                      rows' ghost set no longer covers every contact; engine A's mark_resident at the
//                      layout is the reference); then, before lay_out:
//     rebalance        slab cuts moved part of the way to the owned counts' quantiles, when the
//                      imbalance of the owned counts passes a threshold
//     migrate          every body whose centre left its slab to its new owner (its rows, shape rows
//                      and the caller's state), merged into the rows that stay by id; engine A's rows
//                      change the same way where they are (Engine::splice_resident: the leaving rows
//                      out, the arrivals in; CUDA: on the device, only the arrivals uploaded;
//                      CONTACTGRID_STEP_MIGRATE=whole: the layout sets them all, set_resident)
//   commit             the moved rows into engine A (nothing when this step's layout or update_frame
//                      wrote them)
//   detect_interior    engine A, all pairs of the owned bodies, on a second thread ...
//   refresh_ghosts     ... while this thread sends every boundary row's position and bounding radius
//                      (scenes with ellipsoids: and orientation, in the same message) to the ranks
//                      that hold it as a ghost (MPI, host-staged: Debian's Open MPI is not
//                      CUDA-aware) and writes engine B's rows
//   detect_boundary    engine B (the pairs of a boundary row with a ghost: step_plan.hpp's report
//                      rule), then the wait for A; every rank agrees on the step's errors
//   collect            this step's contacts (their count, their hash when asked) and times
// and after the steps: contacts (the last step's, this rank's, sorted, global ids), pair_hash_sum,
// gather_bodies (every body on rank 0, for the final scene) and stats.
//
// Between rebuilds a body stays with the rank that owned it at the layout, even when its centre has
// crossed a cut (by less than half the layout's skin): the layout's ghost width is the run's plus the
// layout's skin, so every pair that touches now was within it then, and the ghosts are refreshed
// every step. The engines keep their candidate lists with the skin (EngineOptions::skin;
// Engine::set_skin) and rebuild them at their own checks; over several ranks a layout's skin may be
// a multiple of theirs (StepMotion::layout_skins, CONTACTGRID_STEP_LAYOUT_SKIN; 1 by default: their
// builds fall on the layouts), so that builds go without a migration and a layout in between; on one
// rank the two are the same. With skin 0 a step that moved anything rebuilds.
// --skin auto (EngineOptions::skin_auto): the loop picks the skin with kernels/skin_tuner.hpp from the
// largest displacement per step and the measured cost of its steps (the same on every rank).
//
// A rank holds its bodies in ascending id in both engines (the engines' contacts then come out in
// (id_a, id_b) order with the bits of a run from scratch). Scenes with ellipsoids: A and B hold the
// shape rows too, the ghosts' from the layout's exchange; every step refreshes the ghosts'
// orientations with their positions, in the same message (64 bytes a row instead of 40: cheaper than
// a second message per neighbour, BENCHMARKS.md §10). Semi-axes and bounding radii stay as laid out
// (StepMotion::send_semi_axes sends the semi-axes every step, in a message of their own). One rank
// has no boundary rows, no engine B and nothing to send.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine.hpp"
#include "routing.hpp"
#include "session.hpp"
#include "slab_decomposition.hpp"
#include "stage_names.hpp"
#include "step_bodies.hpp"

namespace cg {

// The stages of a step, as timed (this rank's seconds; StepStats: the median over the steps of the
// maximum over ranks). migrate: rebalance + migrate, rebuild: the rebuild check and lay_out, of the
// steps that rebuilt (0 on the others); step: the wall time from update_frame to the end of
// detect_boundary; halo_pack, halo_mpi, halo_unpack: the parts of halo (the rows gathered and packed
// into the send buffer with B's boundary rows, the MPI exchange, the received rows into B);
// merge_wait: the wait for a migration's merge of the host rows where it was joined outside the
// timed stages (it runs beside the layout and the detection: the caller's next move, the frame),
// counted in the step's mean.
enum class StepStage : int {
  frame,
  migrate,
  rebuild,
  halo,
  interior,
  boundary,
  step,
  halo_pack,
  halo_mpi,
  halo_unpack,
  merge_wait
};
inline constexpr int kStepStageCount = 11;
const char* to_string(StepStage stage);

// Per step the maximum over ranks, then the median over the steps.
struct StepStats {
  int steps = 0;
  std::uint64_t contacts = 0;   // the last step's, summed over ranks (checked: pipeline.cpp)
  std::uint64_t hash = 0;       // the last step's pairs, pair_hash summed over ranks (checked likewise)
  double spin = 0;              // StepMotion::spin of the steps (0: the bodies did not turn)
  double drift = 0;             // StepMotion::drift (0: the centres did not move)
  bool turned = false;          // the ellipsoids turned (a spin and a scene with ellipsoids)
  bool oriented = false;        // the halo carried the ghosts' orientations (a scene with ellipsoids)
  std::uint64_t halo_rows = 0;  // ghost rows refreshed per step (the last layout's), summed over ranks
  double setup = 0;             // the first lay_out (max over ranks)
  double frame = 0;             // update_frame: bounds and displacement (engine A), over the ranks, the
                                // frame (the write of the moved positions into A is not timed)
  double migrate = 0;           // per step that rebuilt: rebalance + migrate (median)
  double rebuild = 0;           // per step that rebuilt: the rebuild check + lay_out (median)
  double halo = 0;              // refresh_ghosts: boundary rows (and orientations) through MPI, into B
  double halo_pack = 0, halo_mpi = 0, halo_unpack = 0;  // its parts (StepStage)
  bool halo_on_device = false;  // the halo moved the rows where they are (CONTACTGRID_STEP_HALO)
  double merge_wait = 0;        // per step that waited for the host merge (median; StepStage)
  double interior = 0;          // the owned bodies alone (all their pairs), overlapping the halo
  double boundary = 0;          // the boundary rows against the ghosts, after the halo
  double step = 0;              // wall time of a step (every step)
  double step_mean = 0;         // ... its mean over the steps (rebuilds and reuses together)
  double detect_mean = 0;       // ... the same less the frame (the bodies' motion: not the detection's)
  double detect_build = 0, detect_reuse = 0;  // interior + boundary: median of the steps that built
                                              // the candidate lists, of those that reused them
  StageTimes stages;                          // the engine's stages of the interior detection
  StageTimes build_stages;                    // ... their medians over the steps that built alone
  // rebuilds of the rows (the first layout not counted), bodies that changed rank (summed), slab
  // rebalances, the owned bodies per rank at the end
  std::uint64_t rebuilds = 0, migrated = 0, rebalances = 0, owned_min = 0, owned_max = 0;
  // engine A's candidate lists built and reused over the steps (rank 0's), and the skin of the last
  // layout (auto: the one chosen)
  std::uint64_t builds = 0, reuses = 0;
  double skin = 0;
  bool skin_auto = false;
  std::vector<std::uint64_t> step_contacts;  // per step, summed over ranks
  std::vector<std::uint64_t> step_hashes;    // StepMotion::hash_every_step: contacts_hash, summed
};

// How the loop rebalances the slabs at a rebuild.
struct StepBalance {
  double threshold = 0.1;  // rebalance when max owned / mean owned - 1 exceeds it
  double fraction = 0.5;   // move each cut this far toward its quantile of the owned centres
  std::uint64_t max_sample = 1u << 20;
};

// The steps of one rank: engine A (the run's engine), engine B, the bodies and their plan.
template <class Real>
class StepLoop {
 public:
  // `engine`: the rank's engine (A; the loop sets its rows and its skin: EngineOptions::skin, or
  // skin_auto for the loop's choice); `slabs`: the run's. Every rank constructs one; the stages below
  // are collective, in the order above, update_frame first (the frame of the bodies set).
  StepLoop(Session& session, Engine<Real>& engine, const SlabDecomposition& slabs, const StepMotion& motion,
           int threads, const StepBalance& balance = {});
  ~StepLoop();
  StepLoop(const StepLoop&) = delete;
  StepLoop& operator=(const StepLoop&) = delete;

  // This rank's owned bodies, ascending id: the caller sets them before the first lay_out and moves
  // them (with the state it attached) between steps; they migrate at rebuilds.
  StepBodies& bodies();
  const SlabDecomposition& slabs() const;
  const Frame& frame() const;
  // The halo of the last layout: bodies() rows [offsets[r], offsets[r + 1]) of `rows` go to rank r as
  // ghosts, each group ascending (a caller's per-body state that the ghosts need travels the same
  // way: contactgrid simulate's velocities).
  const ExportPlan& halo() const;

  // Collective. InputError naming the first body that this rank does not own. Engine A's rows are
  // set again only when they are not the bodies' (the setup; a migration under CONTACTGRID_STEP_MIGRATE=
  // whole): else update_frame wrote their motion, migrate spliced them, and the next detection builds;
  // one rank has no plan, no halo and no engine B to lay out.
  void lay_out();
  // Collective. `step`: the step's number (for the messages).
  void update_frame(int step);
  bool rebuild_due();  // collective
  void rebalance();    // collective
  void migrate();      // collective
  // The caller changed the positions (and bounding radii) and/or the orientations of bodies():
  // written into engine A's rows (the integrator's part, before the step's clock). Every step, after
  // the layout when there is one.
  void commit(Moved moved);

  void detect_interior();  // collective (with refresh_ghosts and detect_boundary: one step)
  void refresh_ghosts();
  void detect_boundary();
  void collect();  // collective

  // This rank's contacts of the last step: its engines' rows with global ids, sorted by (id_a, id_b)
  // (CUDA: downloaded now). The run's collect stage gathers them.
  Contacts<Real> contacts();
  // Collective, after the steps: the order-free hash of the last step's pairs summed over ranks.
  std::uint64_t pair_hash_sum();
  // Collective: every rank's bodies on rank 0 in ascending id (the others: none).
  StepBodies gather_bodies();
  StepStats stats();  // collective

 private:
  struct State;
  std::unique_ptr<State> m;
};

extern template class StepLoop<float>;
extern template class StepLoop<double>;

}  // namespace cg
