#pragma once
// The resident steps of a `detect` run (--steps N), called by the pipeline (run/pipeline.cpp) after the
// run's detection and collection: the rows laid out, then per step the motion (the integrator's part,
// before the step's clock: --drift moves every centre, --spin turns the ellipsoids), the frame of the
// moved bodies and, when they moved beyond the skin, a rebuild (rebalance, migrate, lay out), the
// interior detection, the ghost refresh, the boundary detection and the collection
// (comm/resident_steps.hpp: StepLoop).
#include <optional>
#include <string>

#include "engine.hpp"
#include "run/distributed_detect.hpp"
#include "session.hpp"
#include "slab_decomposition.hpp"

namespace cg {

// The steps from the run's engine input. With --drift the last step's contacts are left in `last`
// for the caller to collect as the run's; without, the last step is checked against the run (no
// motion: the same pairs) or against a detection of the turned bodies from scratch (--spin).
// --final-scene: the last step's bodies written as a scene file. Collective.
template <class Real>
StepStats run_steps(Session& session, Engine<Real>& engine, const SlabDecomposition& slabs,
                    const EngineInput& input, const DistributedResult<Real>& result,
                    const DistributedOptions& options, int threads, std::optional<Contacts<Real>>& last);

// --drift: the bodies reach at most steps·|drift| beyond the file's bounds. A reach that takes them
// out of the coordinate range of the run's mode (fp32's world check, the float grid's cells per axis)
// is refused before any step (InputError naming the modes that hold it). Collective.
template <class Real>
void check_drift_range(const Session& session, const std::string& path, const Bounds& global,
                       const DistributedOptions& options);

}  // namespace cg
