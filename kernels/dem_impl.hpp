#pragma once
// The simulation's state behind Simulation<Real>::m_impl, shared by the files that define its members:
// dem.cpp (the sequence of a step) and dem_rows.cpp (one rank's rows of a run over several ranks: the
// rows' records, the halo, the overlapped step, the state). Private to the library: not installed.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "core/dem_step.hpp"
#include "dem.hpp"
#include "dem_backend.hpp"
#include "dem_slots.hpp"
#include "host/dem_stages.hpp"
#include "timing.hpp"

namespace cg {

template <class Real>
struct Simulation<Real>::Impl {
  DemOptions options;
  double alpha = 0;
  dem::StepConstants constants{};
  Engine<Real> engine;
  Backend resolved = Backend::cpu;
  int threads = 1;
  detail::host::HostDem host;
  std::unique_ptr<detail::CudaDem> cuda;
  // the slots path (dem_slots.hpp; null: the rows path, this file's engine detecting contact rows)
  std::unique_ptr<detail::SlotPath<Real>> slots;
  DemBodies start;  // the bodies as given (shape rows, radii: what the state does not change)
  std::uint64_t steps = 0;
  std::size_t contact_count = 0;
  Contacts<Real> contacts;  // CPU: the last step's; CUDA: downloaded on request
  bool contacts_downloaded = false;
  DeviceContactsView<Real> device_contacts{};
  // CUDA: the device state already holds this step's kick_drift (done by the last step's body stage)
  bool drifted = false;
  // DemOptions::stage_times: on during step(); the sums (DemStageTimes)
  bool timing = false;
  double stage_seconds[detail::kDemStages] = {};
  WallClock::time_point last_mark{};
  DemStageTimes times;
  // one rank's rows of a run over several ranks (dem.hpp): their global ids (empty: row i is body i),
  // the frame of every detection, the CPU's positions when the rows were set (CUDA: CudaDem::mark)
  std::vector<std::int64_t> ids;
  std::optional<Frame> frame;
  std::vector<Vec3<double>> marked;
  // set_halo's rows (the CPU's; CUDA keeps them on the device) and the CPU's records of them
  std::vector<std::uint32_t> halo_send, halo_receive;
  std::vector<std::byte> halo_out, halo_in;
  bool halo_set = false;
  bool halo_spheres = false;  // the halo's records are DemSphereRow (else DemRow)
  // the CPU's edge flags (the halo's rows, sent or received: the overlapped step's first pass)
  std::vector<std::uint8_t> edge;

  static EngineOptions engine_options(EngineOptions e) {
    e.history = true;
    e.fields = Fields::basic;
    return e;
  }
  explicit Impl(const DemOptions& o) : options(o), engine(engine_options(o.engine)) {}

  BodiesView host_view() {
    BodiesView v{host.position, host.radius, ids, {}};
    if (!host.shape.empty()) {
      v.shape = host.shape;
      v.semi_axes = host.semi_axes;
      v.orientation = host.orientation;
    }
    return v;
  }

  // Host contacts carry the rows' ids (BodiesView::id): back to row indices, as the device's are
  // (the rows being in id order, the rows' order stays).
  void local_ids(Contacts<Real>& c) const {
    const std::ptrdiff_t k = static_cast<std::ptrdiff_t>(c.size());
    const std::int64_t* first = ids.data();
    const std::int64_t* last = first + ids.size();
    auto row = [&](std::int64_t id) {
      const std::int64_t* at = std::lower_bound(first, last, id);
      if (at == last || *at != id) throw Error("simulate: a contact's body is not a row: internal error");
      return static_cast<std::int64_t>(at - first);
    };
    bool bad = false;
#pragma omp parallel for num_threads(threads) schedule(static) if (k > 65536) reduction(|| : bad)
    for (std::ptrdiff_t r = 0; r < k; ++r) {
      try {
        c.id_a[r] = row(c.id_a[r]);
        c.id_b[r] = row(c.id_b[r]);
      } catch (const Error&) {
        bad = true;
      }
    }
    if (bad) throw Error("simulate: a contact's body is not a row: internal error");
  }

  // The end of a stage of a timed step (CUDA: an event; CPU: the wall clock).
  void mark(detail::DemStage s) {
    if (!timing) return;
    if (resolved == Backend::cuda) {
      detail::cuda_dem_time_mark(*cuda, s);
      return;
    }
    const WallClock::time_point now = WallClock::now();
    stage_seconds[static_cast<int>(s)] += std::chrono::duration<double>(now - last_mark).count();
    last_mark = now;
  }
  void detected() {
    mark(detail::DemStage::detect);
    if (!timing) return;
    for (const StageTime& t : slots ? slots->times() : engine.times()) {
      auto at = std::find_if(times.detection.begin(), times.detection.end(),
                             [&](const StageTime& x) { return x.name == t.name; });
      if (at == times.detection.end())
        times.detection.push_back(t);
      else
        at->seconds += t.seconds;
    }
  }

  // The contacts at the current positions and the forces from them; CUDA: then `then` (the body
  // stage's pass over the bodies integrates them too).
  void forces(detail::DemThen then = detail::DemThen::nothing) {
    if (slots) {  // the kept candidates' slots: no contact rows (dem_slots.hpp)
      if (resolved == Backend::cuda) {
        slots->cuda_detect(*cuda, engine);
        detected();
        slots->cuda_forces(*cuda, constants, then);
      } else {
        slots->host_detect(host, threads);
        detected();
        slots->host_forces(host, constants, threads);
      }
      mark(detail::DemStage::body_terms);
      contacts_downloaded = false;
      return;
    }
    if (resolved == Backend::cuda) {
      device_contacts = engine.detect_device_resident(detail::cuda_dem_bodies(*cuda), frame);
      detected();
      contact_count = device_contacts.count;
      contacts_downloaded = false;
      detail::cuda_dem_forces(*cuda, device_contacts, constants, then);  // marks its stages
      return;
    }
    contacts = engine.detect(host_view(), frame);
    if (!ids.empty()) local_ids(contacts);
    detected();
    contact_count = contacts.size();
    const dem::ContactRows<Real> rows = host_rows();
    detail::host::dem_contact_forces(host, rows, constants, threads);
    mark(detail::DemStage::contact_terms);
    detail::host::dem_body_forces(host, rows, constants, threads);
    mark(detail::DemStage::body_terms);
  }

  // The CPU's contact rows of the step (contacts, row indices).
  dem::ContactRows<Real> host_rows() const {
    return {contacts.id_a.data(),          contacts.id_b.data(),
            contacts.position_on_a.data(), contacts.position_on_b.data(),
            contacts.normal_on_b.data(),   contacts.distance.data(),
            contacts.previous_row.data(),  contacts.size()};
  }

  // One step; `another`: the next step follows with nothing between (CUDA: this step's body stage
  // also does the next one's kick_drift, one pass over the bodies fewer; the same bits).
  void step(bool another) {
    const double dt = options.dt;
    timing = options.stage_times;
    if (resolved == Backend::cuda) {
      if (timing) detail::cuda_dem_time_start(*cuda);
      if (!drifted) detail::cuda_dem_kick_drift(*cuda, dt);
      mark(detail::DemStage::kick_drift);
      drifted = false;
      forces(another ? detail::DemThen::kick_and_drift : detail::DemThen::kick);  // kick: in body_terms
      drifted = another;
      mark(detail::DemStage::kick);
      if (timing) detail::cuda_dem_time_collect(*cuda, stage_seconds);
    } else {
      last_mark = WallClock::now();
      detail::host::dem_kick_drift(host, dt, threads);
      mark(detail::DemStage::kick_drift);
      forces();
      detail::host::dem_kick(host, dt, threads);
      mark(detail::DemStage::kick);
    }
    if (timing) ++times.steps;
    timing = false;
    ++steps;
  }
};

}  // namespace cg
