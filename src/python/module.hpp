#pragma once
// The C++ side of `import contactgrid` (pybind11): the objects the module binds (module.cpp) and how
// they turn Python arrays into the engine's views and the engine's results into Python arrays.
//   inputs.cpp           NumPy arrays → BodiesView (float64 C order read in place, anything else converted
//                        once); __cuda_array_interface__ arrays → DeviceBodiesView (read in place)
//   dlpack.cpp           the DLPack protocol both ways: arrays exposing __dlpack__ taken in place (GPU
//                        ones as device bodies, CPU ones as NumPy arrays), DeviceArray.__dlpack__
//   engine_object.cpp    PyEngine: the options as words, the precision mode (auto: chosen on the first
//                        call from its bodies, as `detect --precision auto`), the engine kept between
//                        calls, its contact history (history=True)
//   contacts_object.cpp  PyContacts: the engine's result, its fields (the optional groups it computed)
//                        as NumPy arrays over the result's own storage (host) or as DeviceArray objects
//                        exposing __cuda_array_interface__ and DLPack (device); DeviceArray
//   files.cpp            the scene and contact files
// The GIL is released around every engine call and file access; a mutex per engine orders calls
// from several Python threads.
#include <dlpack/dlpack.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "engine.hpp"
#include "precision_choice.hpp"
#include "scene/scene.hpp"

namespace cg::python {

namespace py = pybind11;
using Doubles = py::array_t<double, py::array::c_style | py::array::forcecast>;

// ---- inputs --------------------------------------------------------------------------------------

// The bodies of one call from NumPy (or anything np.asarray takes). positions (N, 3); radii (N) or a
// number (every body); semi_axes (N, 3) and orientations (N, 4, w x y z; None: identity) for scenes
// with ellipsoids, where a body whose three semi-axes are equal is a sphere (the engine's closed form)
// and radii, when given, must be each body's largest semi-axis (None: taken from semi_axes).
// float64 C-order arrays are read in place; any other dtype or layout is converted to float64 C order
// once (a copy). Holds what it converted and the shape rows it made; view() is valid while it lives.
class HostBodies {
 public:
  HostBodies(const py::object& positions, const py::object& radii, const py::object& semi_axes,
             const py::object& orientations);
  BodiesView view() const;
  std::size_t size() const { return m_count; }
  bool has_shapes() const { return !m_shape.empty(); }

 private:
  std::size_t m_count = 0;
  Doubles m_position, m_radius, m_semi_axes, m_orientation;
  bool m_radius_given = false, m_orientation_given = false;  // (an empty Doubles is not null)
  std::vector<double> m_radius_made;                         // radii from semi_axes or a number
  std::vector<Quat<double>> m_identity;                      // orientations None
  HostVector<Shape> m_shape;
};

// A tensor taken through the DLPack protocol (dlpack/dlpack.h): the producer's DLManagedTensor, whose
// capsule was renamed "used_dltensor" as the protocol asks; the producer's deleter runs when the last
// holder goes. Holders drop it with the GIL held (producers release Python objects in the deleter).
using DLPackHold = std::shared_ptr<const DLManagedTensor>;

// The DLPack device type `x.__dlpack_device__()` names, when `x` exposes __dlpack__ and
// __dlpack_device__ and is not a NumPy array (those take the NumPy path); none otherwise.
std::optional<int> dlpack_device_type(const py::handle& x);
// Consumes `x.__dlpack__(...)` (stream: for a CUDA producer the legacy default stream, 1, which
// DeviceBodies then waits for; none for a CPU one). ValueError naming `name` for a producer that
// breaks the protocol.
DLPackHold take_dlpack(const py::object& x, const char* name, bool cuda);
// A CPU DLPack tensor as a NumPy array over its memory (any number dtype and strides; no copy), which
// keeps the tensor until it goes.
py::array dlpack_host_array(const py::object& x, const char* name);

// The bodies of one call from GPU arrays: objects exposing __cuda_array_interface__ (v2 or v3) or
// DLPack (__dlpack__ on a CUDA device): float64, C order (strides None or contiguous), positions
// (N, 3), radii (N); read in place (never copied). Spheres only: scenes with ellipsoids come as NumPy
// arrays. A v3 `stream` (DLPack: the legacy default stream it was handed) is waited for before the
// engine reads; the DLPack tensors are held until this object goes.
class DeviceBodies {
 public:
  DeviceBodies(const py::object& positions, const py::object& radii, const py::object& semi_axes,
               const py::object& orientations);
  const DeviceBodiesView& view() const { return m_view; }
  // The streams the producers named (0: none); synchronize() waits for them (GIL released).
  void synchronize() const;

 private:
  DeviceBodiesView m_view;
  std::vector<std::uintptr_t> m_streams;
  std::vector<DLPackHold> m_held;
};

// True when `x` is a GPU array: it exposes __cuda_array_interface__, or DLPack on a CUDA device.
bool is_device_array(const py::handle& x);

// `x` as float64 rows of `columns` values, C order (read in place when it is one, else converted once);
// `n`: the number of rows required. ValueError naming `name` and the shape otherwise.
Doubles float64_rows(const py::object& x, const char* name, py::ssize_t columns,
                     std::optional<std::size_t> n);

// ---- results -------------------------------------------------------------------------------------

class PyEngine;

// What the run that made a result says about itself.
struct RunRecord {
  Precision precision = Precision::fp64;
  std::string precision_reason;  // precision "auto": why that mode (choose_precision's line)
  Backend backend = Backend::cpu;
  std::uint64_t bodies = 0;
  StageTimes times;
  EngineStats stats;
  Attributes attributes;  // read_contacts: the file's root attributes
};

// One detection's contacts. Host: the engine's Contacts<Real>, owned here; its fields are NumPy arrays
// over this storage (no copy), kept alive by the arrays. Device: the engine's DeviceContactsView, valid
// until that engine's next detection (then every field access raises); the engine is kept alive.
class PyContacts {
 public:
  template <class Real>
  PyContacts(Contacts<Real>&& host, RunRecord record)
      : m_host(std::move(host)), m_record(std::move(record)) {}
  template <class Real>
  PyContacts(const DeviceContactsView<Real>& device, RunRecord record, py::object engine,
             std::shared_ptr<const std::uint64_t> generation)
      : m_device(device),
        m_record(std::move(record)),
        m_engine(std::move(engine)),
        m_generation(std::move(generation)),
        m_made_at(*m_generation) {}

  std::size_t size() const;
  bool on_device() const { return !std::holds_alternative<std::monostate>(m_device); }
  bool full() const { return fields().full; }
  bool history() const { return fields().history; }
  FieldSet fields() const;  // the optional groups computed
  const RunRecord& record() const { return m_record; }
  std::vector<std::string> names() const;  // the fields present, in docs/FORMAT.md §2 order

  // A field by name (KeyError for an unknown one or an optional one not computed, naming the option
  // that computes it): a NumPy array
  // viewing this object's storage (base: self) or, on the device, a DeviceArray viewing the engine's.
  py::object field(const py::object& self, const std::string& name) const;
  // Host contacts: self. Device: one copy of every field to host memory.
  py::object to_host(const py::object& self) const;
  // The file a `detect -o` run writes (docs/FORMAT.md §2), with this run's record.
  void write(const std::string& path) const;

 private:
  void check_current() const;
  std::variant<std::monostate, Contacts<float>, Contacts<double>> m_host;
  std::variant<std::monostate, DeviceContactsView<float>, DeviceContactsView<double>> m_device;
  RunRecord m_record;
  py::object m_engine;  // device: the PyEngine whose workspace holds the rows
  std::shared_ptr<const std::uint64_t> m_generation;
  std::uint64_t m_made_at = 0;
};

// Device memory exposed as __cuda_array_interface__ v3: either owned (DeviceArray(numpy_array) copies
// a NumPy array to the GPU; freed with the object) or a view of memory another object owns (the
// fields of device contacts; `owner` kept alive).
class DeviceArray {
 public:
  DeviceArray(const py::array& host);  // owned copy of `host`
  DeviceArray(std::uintptr_t pointer, std::vector<py::ssize_t> shape, py::dtype dtype, py::object owner);
  ~DeviceArray();
  DeviceArray(const DeviceArray&) = delete;
  DeviceArray& operator=(const DeviceArray&) = delete;

  py::dict interface() const;  // __cuda_array_interface__
  // DLPack (dlpack.cpp): a "dltensor" capsule over this memory whose deleter holds `self` (and so the
  // owner) alive until the consumer calls it; the device as (kDLCUDA, device id).
  static py::capsule dlpack(const py::object& self, const py::object& stream, const py::object& max_version,
                            const py::object& dl_device, const py::object& copy);
  py::tuple dlpack_device() const;
  py::array copy_to_host() const;
  const std::vector<py::ssize_t>& shape() const { return m_shape; }
  py::dtype dtype() const { return m_dtype; }
  std::uintptr_t pointer() const { return m_pointer; }

 private:
  std::uintptr_t m_pointer = 0;
  std::vector<py::ssize_t> m_shape;
  py::dtype m_dtype;
  py::object m_owner;  // none: owned
  bool m_owned = false;
};

// A run's counters and stage times as Python dicts (name → value, in the engine's order).
py::dict stats_dict(const EngineStats& stats);
py::dict times_dict(const StageTimes& times);

// ---- files (docs/FORMAT.md §1, §2) ----------------------------------------------------------------------
// read_scene: a dict of positions, radii (every body, in id order: spheres, then ellipsoids) and, for
// scenes with ellipsoids, semi_axes and orientations (spheres: (r, r, r) and identity), the root
// attributes, radius_low/radius_high, and the sphere and ellipsoid counts. Arrays own the rows read
// (no copy).
py::dict read_scene_file(const std::string& path);
// write_scene: bodies as HostBodies takes them; spheres (equal semi-axes) must come before ellipsoids
// (a file numbers its spheres first).
void write_scene_file(const std::string& path, const py::object& positions, const py::object& radii,
                      const py::object& semi_axes, const py::object& orientations, const py::dict& attributes,
                      std::optional<double> radius_low, std::optional<double> radius_high);
// read_contacts: float64 arrays whatever the file's precision; the record holds its root attributes.
PyContacts read_contacts_file(const std::string& path);

// ---- the engine ----------------------------------------------------------------------------------

// The words of the module's options (ValueError for any other word).
Backend backend_of(const std::string& word);
std::optional<Precision> precision_of_word(const std::string& word);  // "auto": none
Fields fields_of(const std::string& word);
Accuracy accuracy_of(const py::object& accuracy);  // None, a number (position) or (position, angle)

// contactgrid.Engine: an engine of one backend and precision mode kept between calls (its workspace,
// its resident bodies, its skin's candidate list). precision "auto" chooses the mode on the first
// call from that call's bodies (as `detect --precision auto`) and keeps it.
class PyEngine {
 public:
  PyEngine(const std::string& backend, const std::string& precision, const py::object& accuracy,
           const std::string& fields, int threads, double skin, int device, bool history);

  // detect(positions, radii, ...) on NumPy or CUDA arrays. `self`: kept by device contacts.
  py::object detect(const py::object& self, const py::object& positions, const py::object& radii,
                    const py::object& semi_axes, const py::object& orientations);

  void set_resident(const py::object& positions, const py::object& radii, const py::object& semi_axes,
                    const py::object& orientations);
  void write_resident(std::size_t first, const py::object& positions, const py::object& radii);
  void write_resident_shapes(std::size_t first, const py::object& semi_axes, const py::object& orientations);
  py::tuple read_resident(std::size_t first, std::optional<std::size_t> count);
  // Host contacts (a copy of the engine's) on the CPU backend, device contacts on CUDA.
  py::object detect_resident(const py::object& self);
  std::size_t resident_size();
  // history=True: the next call's pairs are all new.
  void reset_history();

  std::string backend() const;
  std::optional<std::string> precision() const;  // none until chosen
  py::dict stats();                              // of the last call
  py::dict times();                              // of the last call

 private:
  // Makes the engine of the mode `fixed` or (auto) chosen from these bounds; no-op once made.
  void make(const std::optional<Bounds>& bounds, bool ellipsoids);
  template <class F>
  auto with_engine(F&& f);
  RunRecord record(std::uint64_t bodies) const;
  void bump() { ++*m_generation; }

  EngineOptions m_options;
  std::optional<Precision> m_fixed;
  Accuracy m_accuracy;
  Backend m_backend = Backend::cpu;  // resolved
  std::optional<Precision> m_mode;
  std::string m_reason;
  std::variant<std::monostate, std::unique_ptr<Engine<float>>, std::unique_ptr<Engine<double>>> m_engine;
  std::shared_ptr<std::uint64_t> m_generation = std::make_shared<std::uint64_t>(0);
  std::mutex m_mutex;
};

}  // namespace cg::python
