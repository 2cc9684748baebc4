#pragma once
// Internal interface between the granular dynamics (dem.cpp: setup, the sequence of a step, the
// engine's calls) and its CUDA backend (cuda/dem_backend.cu; the CPU backend is host/dem_stages.hpp).
// The CUDA backend keeps every array in DEVICE memory; the engine detects on them through
// detect_device_resident, and its contacts never leave the device.
#include <memory>

#include "core/dem_step.hpp"
#include "core/narrow.hpp"
#include "dem.hpp"

namespace cg::detail {

// The stages of a step in order, as DemOptions::stage_times reports them (dem.hpp: DemStageTimes).
//   kick_drift     the first half kick and the drift of every body
//   detect         the engine's detection with history (its own stages: DemStageTimes::detection)
//   contact_terms  each contact's force, torques and spring
//   body_index     where each body's rows lie as A and as B (the order of its sums)
//   body_terms     each body's sums in that order, walls, gravity (CUDA: and the body's kick, and
//                  the next step's kick_drift where one follows: DemThen)
//   kick           the second half kick (CPU; CUDA: in body_terms, its stage empty)
enum class DemStage : int { kick_drift, detect, contact_terms, body_index, body_terms, kick };
constexpr int kDemStages = 6;
inline const char* dem_stage_name(int s) {
  constexpr const char* names[kDemStages] = {"kick_drift", "detect",     "contact_terms",
                                             "body_index", "body_terms", "kick"};
  return names[s];
}

class CudaDem;
// The bodies and their properties uploaded to `device` (-1: current): CudaError without CUDA.
std::unique_ptr<CudaDem> make_cuda_dem(int device, const DemBodies& bodies,
                                       const std::vector<dem::BodyProps>& props,
                                       const std::vector<dem::Wall>& walls);
void destroy(CudaDem* dem);
// The bodies as the engine reads them (DEVICE).
DeviceBodiesView cuda_dem_bodies(CudaDem& dem);
void cuda_dem_kick_drift(CudaDem& dem, double dt);
// What the body stage does after a body's force and torque (one pass over the bodies, where each
// body's step reads only its own state): nothing (the forces of the start), the step's second half
// kick, or that kick and then the next step's kick_drift (a step followed by another with nothing
// between them). The same operations in the same order as the separate stages: the same bits.
enum class DemThen : int { nothing, kick, kick_and_drift };
// contact_terms then the order by B and body_terms, on the device, over the engine's device contacts
// (c.walls is replaced by the device copy of the walls), then `then` with c.dt.
template <class Real>
void cuda_dem_forces(CudaDem& dem, const DeviceContactsView<Real>& contacts, const dem::StepConstants& c,
                     DemThen then);
DemEnergies cuda_dem_energies(CudaDem& dem, std::size_t contacts, Vec3<double> gravity);
// The step's stage events (DemStage): on from now, the step's start, a stage's end, and the seconds
// of the last step's marked stages added to seconds[kDemStages] (waits for its last event).
void cuda_dem_time_enable(CudaDem& dem);
void cuda_dem_time_start(CudaDem& dem);
void cuda_dem_time_mark(CudaDem& dem, DemStage stage);
void cuda_dem_time_collect(CudaDem& dem, double* seconds);
// The current state into `out` (positions, velocities, spins, orientations; the rest kept).
void cuda_dem_download(CudaDem& dem, DemBodies& out);
// One rank's rows of a run over several ranks (dem.hpp: Simulation's rank interface; cuda/dem_rows.cuh):
// the rows' global ids (the engine's history keys), the state (DemRow) of some rows out and in, the
// largest displacement since the mark (set at the rows' upload and by cuda_dem_mark), and everything
// the rows carry (DemState without its history: the engine's) out and in, `contacts` the last step's.
void cuda_dem_set_ids(CudaDem& dem, const std::vector<std::int64_t>& ids);
void cuda_dem_read_rows(CudaDem& dem, const std::vector<std::uint32_t>& rows, std::vector<DemRow>& out);
void cuda_dem_write_rows(CudaDem& dem, const std::vector<std::uint32_t>& rows, const std::vector<DemRow>& in);
// The halo's rows kept on the device, their records through page-locked buffers (Simulation::set_halo).
// spheres: the records are DemSphereRow (else DemRow).
void cuda_dem_set_halo(CudaDem& dem, const std::vector<std::uint32_t>& send,
                       const std::vector<std::uint32_t>& receive, bool spheres);
const std::byte* cuda_dem_gather_halo(CudaDem& dem);
std::byte* cuda_dem_halo_inbox(CudaDem& dem);
void cuda_dem_scatter_halo(CudaDem& dem);
// The overlapped step (Simulation::finish_step_sending): the body index, the edge's contact and body
// terms (edge flags and rows from cuda_dem_set_halo) with the kick and the next kick_drift, the sent
// rows' gather and download on the halo's stream, the interior's passes enqueued behind the edge's;
// returns the records once downloaded. cuda_dem_receive_halo: the inbox uploaded and scattered on
// the halo's stream, the legacy stream's later work ordered after it. cuda_dem_interior_seconds:
// the last overlapped step's interior passes on the device after the records' download (stage
// times only; waits for them).
bool cuda_dem_can_overlap(const CudaDem& dem);
template <class Real>
const std::byte* cuda_dem_forces_sending(CudaDem& dem, const DeviceContactsView<Real>& contacts,
                                         const dem::StepConstants& c);
void cuda_dem_receive_halo(CudaDem& dem);
double cuda_dem_interior_seconds(CudaDem& dem);
void cuda_dem_mark(CudaDem& dem);
double cuda_dem_displacement(CudaDem& dem);
void cuda_dem_get_state(CudaDem& dem, std::size_t contacts, DemState& out);
void cuda_dem_log_terms(CudaDem& dem, const std::vector<std::uint32_t>& rows, Vec3<double> gravity,
                        std::size_t contacts, std::vector<DemLogRow>& out,
                        std::vector<double>& contact_energy);
void cuda_dem_set_state(CudaDem& dem, const DemState& in);

// The slots path on the device (kernels/dem_slots.hpp; cuda/dem_slots.cu): the slots' state; a
// rebuild's inflated radii (the candidate engine's bodies) and the list from its device contacts;
// a step's start (no rebuild: the previous rows of the last rebuild expire) and forces, then `then`;
// the last step's contacts: their number, their energies into the contact energies that
// cuda_dem_energies sums, their rows with history (made on the host from the device's arrays).
class CudaSlots;
std::unique_ptr<CudaSlots> make_cuda_slots();
void destroy(CudaSlots* s);
DeviceBodiesView cuda_slots_inflate(CudaDem& d, CudaSlots& s, double inflation);
template <class Real>
void cuda_slots_rebuild(CudaDem& d, CudaSlots& s, const DeviceContactsView<Real>& pairs);
void cuda_slots_step_begins(CudaSlots& s);
template <class Real>
void cuda_slots_forces(CudaDem& d, CudaSlots& s, const NarrowBodies<Real>& world, dem::StepConstants c,
                       DemThen then);
std::size_t cuda_slots_contact_count(CudaDem& d, CudaSlots& s);
void cuda_slots_contact_energies(CudaDem& d, CudaSlots& s, std::size_t contacts);
template <class Real>
Contacts<Real> cuda_slots_contacts(CudaDem& d, CudaSlots& s);

}  // namespace cg::detail

template <>
struct std::default_delete<cg::detail::CudaSlots> {
  void operator()(cg::detail::CudaSlots* p) const { cg::detail::destroy(p); }
};

template <>
struct std::default_delete<cg::detail::CudaDem> {
  void operator()(cg::detail::CudaDem* p) const { cg::detail::destroy(p); }
};
