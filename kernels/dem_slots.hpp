#pragma once
// The granular dynamics' slots path (opt-in: CONTACTGRID_DEM_PATH=slots, scenes of spheres on one rank; the
// per-item functions and their data flow are core/dem_slots.hpp): the step works on a kept candidate list,
// not on contact rows. Each step:
//   bounds     the bodies' bounds (validated as the engine validates them), the frame's origin
//              (their low corner, as the engine's frame) and the skin check of the engine
//              (core/skin.hpp, Engine's plan: the list's coordinate bound, the largest displacement
//              since its build): the same decision, step by step, as the engine of the rows path
//   build      when the check fails: the candidates are the contacts of an engine detection of the
//              bodies with radii inflated by the engine's skin_inflation (the engine's own pair and
//              narrow stages, no history), each body's index, and the slots' state carried over
//              (remap_slot: one search of the old pair keys per new slot, at a rebuild only)
//   forces     slot_body_terms of every body: narrow test, Hertz–Mindlin, sums, walls, gravity
// A contact row exists only when a caller asks (contacts(), energies()): made from the slots (the
// same narrow function on the same positions), the same bits as the rows path's rows.
// Not on this path (the rows path, kernels/dem.cpp, runs them): scenes with ellipsoids, a rank of a run
// over several ranks (ids or a frame given), no skin or an automatic one, and without the knob.
#include <cstddef>
#include <memory>
#include <optional>

#include "dem.hpp"
#include "dem_backend.hpp"
#include "timing.hpp"

namespace cg::detail {

namespace host {
struct HostDem;
struct HostSlots;
}  // namespace host

// True when a simulation of `bodies` with `options` (single rank) takes the slots path.
bool slots_path_wanted(const DemBodies& bodies, const DemOptions& options, bool ranked);

template <class Real>
class SlotPath {
 public:
  explicit SlotPath(const EngineOptions& engine);
  ~SlotPath();
  // One step's detection (bounds, the skin check, a build when it fails; CUDA: `main` is the
  // simulation's engine, its bounds on the device) and forces, CPU (host's forces replaced by the
  // step's) or CUDA (`then` as cuda_dem_forces).
  void host_detect(host::HostDem& h, int threads);
  void host_forces(host::HostDem& h, const dem::StepConstants& c, int threads);
  void cuda_detect(CudaDem& d, Engine<Real>& main);
  void cuda_forces(CudaDem& d, const dem::StepConstants& c, DemThen then);
  // The last step's contacts: their number, energies into the backend's contact energies (what
  // dem_energies and cuda_dem_energies sum), rows with history.
  std::size_t contact_count(CudaDem* d) const { return contact_count_of(d); }
  void contact_energies(host::HostDem& h);
  void cuda_contact_energies(CudaDem& d);  // (after contact_count)
  Contacts<Real> contacts(const host::HostDem* h, CudaDem* d);
  // The engine's counters as the rows path's engine keeps them (candidate builds and reuses, skin).
  const EngineStats& stats() const { return m_stats; }
  // The last detection's stages (DemStageTimes::detection): "skin" (bounds and check), "candidates"
  // (a build: the inflated spheres' detection, the index and the remap; 0 at a reuse).
  const StageTimes& times() const { return m_times; }

 private:
  // The check (Engine's plan_skin and skin_covers with the same values): true to build.
  bool must_build(const Bounds& b, double displacement);
  double inflation(const Bounds& b) const;
  void plan_cell_size(const Bounds& b);
  std::size_t contact_count_of(CudaDem* d) const;
  NarrowBodies<Real> world(const double* position, const double* radius) const;
  void timed(WallClock::time_point t0, WallClock::time_point t1, bool build);

  EngineOptions m_options;
  Engine<Real> m_candidates;  // skin 0, no history: the inflated spheres' contacts
  EngineStats m_stats;
  StageTimes m_times;
  bool m_valid = false;
  double m_bound = 0, m_skin = 0;
  Vec3<double> m_origin{0, 0, 0};
  mutable std::optional<std::size_t> m_count;
  std::unique_ptr<host::HostSlots> m_host;
  std::unique_ptr<CudaSlots> m_cuda;  // CUDA: the slots on the device (made at the first step)
  std::vector<Vec3<double>> m_ref;    // CPU: the positions at the build
  std::vector<double> m_inflated;     // CPU: the radii of a build
};

}  // namespace cg::detail
