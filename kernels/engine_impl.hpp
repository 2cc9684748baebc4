#pragma once
// The engine's state behind Engine<Real>::m_impl, shared by the files that define its members:
// engine.cpp (the calls: their plans, skins and backends) and engine_resident.cpp (the resident bodies
// and their row lists). Private to the library: not installed.
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "backend.hpp"
#include "engine.hpp"
#include "host_vector.hpp"
#include "skin_tuner.hpp"

namespace cg {

template <class Real>
struct Engine<Real>::Impl {
  EngineOptions options;
  Backend resolved = Backend::cpu;
  detail::HostBackend host;
  detail::CudaBackend* cuda = nullptr;
  StageTimes times;
  EngineStats stats;
  // resident bodies of the CPU backend (CUDA keeps them in the backend) and their last contacts
  HostVector<Vec3<double>> resident_position;
  HostVector<double> resident_radius;
  HostVector<std::uint8_t> resident_report;
  HostVector<Shape> resident_shape;  // shape rows (empty: all spheres)
  HostVector<Vec3<double>> resident_semi_axes;
  HostVector<Quat<double>> resident_orientation;
  HostVector<std::int64_t> resident_id;  // the rows' global ids (history keys); empty: row indices
  std::size_t resident_rows = 0;
  bool resident_shapes = false;                       // set_resident had shape rows (either backend)
  bool resident_marked = false;                       // mark_resident since the rows were set
  HostVector<Vec3<double>> resident_marked_position;  // CPU: the centres at the mark (CUDA: on the device)
  Contacts<Real> resident_contacts;
  std::optional<DeviceContactsView<Real>> resident_on_device;  // CUDA: not yet downloaded
  bool resident_overwritten = false;  // CUDA: a later detection reused the workspace first
  bool rows_any_order = false;        // CUDA: detect_resident's call (DetectJob::any_row_order)
  // set_row_list's lists: their lengths (both backends; set: since the rows were set), the CPU
  // backend's rows and packed-row buffers (CUDA keeps them in the backend)
  std::array<std::size_t, kRowLists> row_list_size{};
  std::array<bool, kRowLists> row_list_set{};
  std::array<std::vector<std::size_t>, kRowLists> row_list;
  HostVector<std::byte> row_gathered, row_scattered;
  std::size_t scattered_rows = 0;
  bool scattered_orientations = false;
  // EngineOptions::skin > 0: what the kept candidate list was built for (the backend keeps the list
  // and the bodies' state); a call that matches it checks the motion, any other call rebuilds.
  struct KeptFor {
    bool valid = false;
    std::size_t count = 0;
    std::vector<std::int64_t> id;  // the bodies' ids (empty: implied, as for device bodies)
    bool shapes = false;           // the scene had ellipsoids
    double coordinate_bound = 0;   // core/skin.hpp: a later call's coordinates must stay within
    double skin = 0;               // the skin it was built with (its check's)
  } kept;
  // EngineOptions::skin_auto: the tuner, and the calls since the last build (this one included)
  SkinTuner tuner;
  int calls_since_build = 0;
  void forget_resident_view() {  // before any detection: the view's storage is reused
    if (resident_on_device) resident_overwritten = true;
    resident_on_device.reset();
  }
  // EngineOptions::history: the previous call's keys and ages, on the host (`history`) or in the
  // CUDA backend's device history (after a device-path call); moved where the next call needs them.
  ContactHistory history;
  bool history_on_device = false;
  void history_to_host() {
    if (history_on_device) detail::history_download(*cuda, history);
    history_on_device = false;
  }
  void history_to_device() {
    if (!history_on_device) detail::history_upload(*cuda, history);
    history_on_device = true;
  }
  // A call without bodies: no contacts, so every pair of the previous call has ended.
  void history_end_all(Contacts<Real>& out) {
    history.clear();
    history_on_device = false;
    out.history = true;
  }
  ~Impl() { detail::destroy(cuda); }
};

// The host-array path: one call on `bodies` with the engine's plan, skin and backend. `history_ids`:
// the keys of the contact history (EngineOptions::history) when the contacts' ids are row indices
// (resident bodies with ids); empty: the contacts' ids. `known`: compute_bounds(bodies), when the
// caller has it. Explicitly instantiated for float and double in engine.cpp.
template <class Real>
Contacts<Real> detect_host(typename Engine<Real>::Impl& s, const BodiesView& bodies,
                           std::optional<Frame> frame, std::span<const std::int64_t> history_ids,
                           const Bounds* known = nullptr);

}  // namespace cg
