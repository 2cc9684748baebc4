// The extension module contactgrid._contactgrid: the bindings and their docstrings. The package's
// __init__.py re-exports it and adds detect() and the Scene mapping; docs/PYTHON.md is the reference.
#include "python/module.hpp"

#include <pybind11/stl.h>

namespace py = pybind11;
using namespace cg::python;

namespace {

const char* const k_engine_doc =
    R"(An engine kept between calls: its workspace (host buffers, or device memory
for the CUDA backend), its resident bodies and, with a skin, its candidate pairs.

Engine(*, backend="auto", precision="auto", accuracy=None, fields="basic", threads=0, skin=0.0, device=-1,
       history=False)

backend    "auto" (CUDA when a GPU is usable, else the CPU), "cpu" or "cuda".
precision  "auto", "fp32", "fp64" or "mixed". "auto" chooses on the first call from that call's bodies
           (the cheapest mode whose documented bounds meet `accuracy`; docs/PRECISION.md)
           and keeps that mode for the engine's life.
accuracy   precision "auto" only: None (what fp64 gives), a number (position error relative to the
           smallest radius) or a pair (position, normal angle in degrees).
fields     "basic" (ids, points, normal, distance) or "full" (also local points, friction directions).
threads    CPU backend threads (0: all cores).
skin       Verlet skin, a world length >= 0: candidate pairs kept across calls while the bodies moved
           less than skin/2 (the contacts are always those of a fresh detection).
device     CUDA device (-1: the current one).
history    contact identity across calls: every call's contacts carry age (calls the pair has touched
           without a break, 0 on its first) and previous_row (its row in this engine's previous
           call's contacts, -1 when new); reset_history() makes every pair of the next call new.)";

const char* const k_detect_doc =
    R"(detect(positions, radii=None, *, semi_axes=None, orientations=None) -> Contacts

Every touching or overlapping pair of the bodies, sorted by (id_a, id_b); body i has id i.
Arrays as contactgrid.detect takes them (NumPy or CPU DLPack arrays, or float64 C-order GPU arrays
exposing __cuda_array_interface__ or __dlpack__ for the CUDA backend, whose contacts then stay on the
GPU). Device contacts are valid until this engine detects again. The GIL is released while the engine
runs.)";

const char* const k_contacts_doc =
    R"(The contacts of one detection (docs/FORMAT.md §2), sorted by (id_a, id_b) with id_a < id_b.

Fields, as attributes or items (contacts.id_a, contacts["id_a"]):
  id_a, id_b (K,) int64; position_on_a, position_on_b, normal_on_b (K, 3); distance (K,)
  with fields="full" also local_point_a, local_point_b, lateral_friction_dir1, lateral_friction_dir2;
  with Engine(history=True) also age, previous_row (K,) int64.
Host contacts: NumPy arrays over the engine's result (no copy; they keep it alive); float32 for
precision "fp32", else float64. Device contacts (on_device): DeviceArray objects exposing
__cuda_array_interface__ and DLPack over the engine's device memory, valid until that engine
detects again.
len(contacts) is K; precision, precision_reason, backend, bodies, times, stats describe the run.)";

}  // namespace

PYBIND11_MODULE(_contactgrid, m) {
  m.doc() = "contactgrid's engine (use the package: import contactgrid)";
  m.attr("__version__") = CONTACTGRID_VERSION;

  // Errors: the CLI's messages, as Python exceptions a caller can also catch by the built-in base.
  auto& error = py::register_exception<cg::Error>(m, "Error", PyExc_RuntimeError);
  py::register_exception<cg::UsageError>(m, "UsageError", PyExc_ValueError);
  py::register_exception<cg::InputError>(m, "InputError", PyExc_ValueError);
  py::register_exception<cg::IoError>(m, "IoError", PyExc_OSError);
  py::register_exception<cg::ResourceError>(m, "ResourceError", PyExc_MemoryError);
  py::register_exception<cg::CudaError>(m, "CudaError", error.ptr());
  py::register_exception<cg::MpiError>(m, "MpiError", error.ptr());

  m.def("cuda_available", &cg::cuda_available,
        "True when a CUDA device is usable (False in builds without CUDA).");
  m.def("cuda_device_count", &cg::cuda_device_count, "The number of usable CUDA devices.");

  py::class_<DeviceArray>(m, "DeviceArray", R"(GPU memory exposed as __cuda_array_interface__ (v3) and DLPack.

DeviceArray(array) copies a NumPy array to the current GPU (C order, its dtype) and frees it with the
object: for callers without CuPy, PyTorch or Numba, and for tests. The fields of device contacts are
DeviceArray views of the engine's memory. copy_to_host() returns a NumPy copy. cupy.from_dlpack(a) and
torch.from_dlpack(a) take it without a copy (the tensor keeps this object alive).)")
      .def(py::init<const py::array&>(), py::arg("array"))
      .def_property_readonly("__cuda_array_interface__", &DeviceArray::interface)
      .def("__dlpack__", &DeviceArray::dlpack, py::kw_only(), py::arg("stream") = py::none(),
           py::arg("max_version") = py::none(), py::arg("dl_device") = py::none(),
           py::arg("copy") = py::none(),
           R"(A DLPack capsule ("dltensor") over this memory, no copy. The memory is complete when exposed,
so any consumer stream may read it at once; copy=True and another dl_device raise BufferError.)")
      .def("__dlpack_device__", &DeviceArray::dlpack_device, "(kDLCUDA = 2, the CUDA device id).")
      .def_property_readonly("shape", [](const DeviceArray& a) { return py::tuple(py::cast(a.shape())); })
      .def_property_readonly("dtype", &DeviceArray::dtype)
      .def_property_readonly("pointer", &DeviceArray::pointer, "The device address of the first element.")
      .def("__len__", [](const DeviceArray& a) { return a.shape().empty() ? 0 : a.shape()[0]; })
      .def("copy_to_host", &DeviceArray::copy_to_host, "A NumPy copy of the array.");

  py::class_<PyContacts>(m, "Contacts", k_contacts_doc)
      .def("__len__", &PyContacts::size)
      .def(
          "__getitem__",
          [](const py::object& self, const std::string& name) {
            return self.cast<const PyContacts&>().field(self, name);
          },
          py::arg("name"))
      .def(
          "__getattr__",
          [](const py::object& self, const std::string& name) -> py::object {
            try {
              return self.cast<const PyContacts&>().field(self, name);
            } catch (const py::key_error&) {
              throw py::attribute_error("'Contacts' has no field '" + name + "'");
            }
          },
          py::arg("name"))
      .def("__contains__",
           [](const PyContacts& c, const std::string& name) {
             for (const auto& n : c.names())
               if (n == name) return true;
             return false;
           })
      .def("keys", &PyContacts::names, "The fields present, in docs/FORMAT.md §2 order.")
      .def("__iter__", [](const PyContacts& c) { return py::iter(py::cast(c.names())); })
      .def("__dir__",
           [](const py::object& self) {
             py::list out = py::module_::import("builtins").attr("object").attr("__dir__")(self);
             for (const auto& n : self.cast<const PyContacts&>().names()) out.append(py::str(n));
             return out;
           })
      .def_property_readonly("on_device", &PyContacts::on_device, "True: the fields are DeviceArray views.")
      .def_property_readonly("full", &PyContacts::full,
                             "True: the optional fields of fields='full' were computed.")
      .def_property_readonly("history", &PyContacts::history,
                             "True: age and previous_row were computed (Engine(history=True)).")
      .def_property_readonly(
          "precision", [](const PyContacts& c) { return cg::to_string(c.record().precision); },
          "The precision mode that ran: 'fp32', 'fp64' or 'mixed'.")
      .def_property_readonly(
          "precision_reason", [](const PyContacts& c) { return c.record().precision_reason; },
          "precision 'auto': why that mode (empty when the mode was given).")
      .def_property_readonly(
          "backend", [](const PyContacts& c) { return cg::to_string(c.record().backend); },
          "'cpu' or 'cuda'.")
      .def_property_readonly(
          "bodies", [](const PyContacts& c) { return c.record().bodies; }, "The number of bodies detected.")
      .def_property_readonly(
          "times", [](const PyContacts& c) { return times_dict(c.record().times); },
          "Seconds per engine stage (plan, pack, entries, sort, pairs, order, narrow, ...).")
      .def_property_readonly(
          "stats", [](const PyContacts& c) { return stats_dict(c.record().stats); },
          "The engine's counters of the run (entries, pair tests, cell size, ...).")
      .def_property_readonly(
          "attributes",
          [](const PyContacts& c) {
            py::dict d;
            for (const auto& [k, v] : c.record().attributes)
              d[py::str(k)] = std::visit([](const auto& x) -> py::object { return py::cast(x); }, v);
            return d;
          },
          "read_contacts: the file's root attributes (else empty).")
      .def(
          "to_host", [](const py::object& self) { return self.cast<const PyContacts&>().to_host(self); },
          "Host contacts: self. Device contacts: a copy of every field in host memory.")
      .def("_check_current",
           [](const py::object& self) {
             if (self.cast<const PyContacts&>().on_device())
               self.cast<const PyContacts&>().field(self, "id_a");
           })
      .def("__repr__", [](const PyContacts& c) {
        return "<contactgrid.Contacts: " + std::to_string(c.size()) + " contacts, " +
               cg::to_string(c.record().precision) + ", " + cg::to_string(c.record().backend) +
               (c.on_device() ? ", on the GPU>" : ">");
      });

  py::class_<PyEngine>(m, "Engine", k_engine_doc)
      .def(py::init<const std::string&, const std::string&, const py::object&, const std::string&, int,
                    double, int, bool>(),
           py::kw_only(), py::arg("backend") = "auto", py::arg("precision") = "auto",
           py::arg("accuracy") = py::none(), py::arg("fields") = "basic", py::arg("threads") = 0,
           py::arg("skin") = 0.0, py::arg("device") = -1, py::arg("history") = false)
      .def(
          "detect",
          [](const py::object& self, const py::object& positions, const py::object& radii,
             const py::object& semi_axes, const py::object& orientations) {
            return self.cast<PyEngine&>().detect(self, positions, radii, semi_axes, orientations);
          },
          py::arg("positions"), py::arg("radii") = py::none(), py::kw_only(),
          py::arg("semi_axes") = py::none(), py::arg("orientations") = py::none(), k_detect_doc)
      .def(
          "set_resident", &PyEngine::set_resident, py::arg("positions"), py::arg("radii") = py::none(),
          py::kw_only(), py::arg("semi_axes") = py::none(), py::arg("orientations") = py::none(),
          R"(Copies the bodies (as detect takes them) to where the backend computes (host memory, or GPU memory
for CUDA) and keeps them between calls; row i is body i. GPU arrays (spheres) are copied through host
memory once.)")
      .def("write_resident", &PyEngine::write_resident, py::arg("first"), py::arg("positions"),
           py::arg("radii"),
           "Overwrites the positions and radii of resident rows [first, first + len(positions)).")
      .def("write_resident_shapes", &PyEngine::write_resident_shapes, py::arg("first"),
           py::arg("semi_axes") = py::none(), py::arg("orientations") = py::none(),
           "Overwrites the semi-axes and/or orientations of resident rows from `first` (None: left alone).")
      .def("read_resident", &PyEngine::read_resident, py::arg("first") = 0, py::arg("count") = py::none(),
           "(positions, radii) of resident rows [first, first + count) (count None: to the end), copied.")
      .def(
          "detect_resident",
          [](const py::object& self) { return self.cast<PyEngine&>().detect_resident(self); },
          "Detects among the resident bodies; host contacts (one copy of the engine's, on either backend).")
      .def("reset_history", &PyEngine::reset_history,
           "history=True: every pair of the next call is new (age 0, previous_row -1).")
      .def_property_readonly("resident_size", &PyEngine::resident_size, "The number of resident rows.")
      .def_property_readonly("backend", &PyEngine::backend, "The resolved backend: 'cpu' or 'cuda'.")
      .def_property_readonly("precision", &PyEngine::precision,
                             "The precision mode ('fp32', 'fp64', 'mixed'), None until 'auto' has chosen.")
      .def_property_readonly("stats", &PyEngine::stats, "The counters of the last call (dict).")
      .def_property_readonly("times", &PyEngine::times, "Seconds per engine stage of the last call (dict).");

  m.def("_read_scene", &read_scene_file, py::arg("path"));
  m.def("_write_scene", &write_scene_file, py::arg("path"), py::arg("positions"), py::arg("radii"),
        py::arg("semi_axes"), py::arg("orientations"), py::arg("attributes"), py::arg("radius_low"),
        py::arg("radius_high"));
  m.def("_read_contacts", &read_contacts_file, py::arg("path"));
  m.def(
      "_write_contacts", [](const std::string& path, const PyContacts& contacts) { contacts.write(path); },
      py::arg("path"), py::arg("contacts"));
}
