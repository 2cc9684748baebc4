// The DLPack protocol (dlpack/dlpack.h; the Python array API's __dlpack__ / __dlpack_device__) both ways
// (module.hpp): arrays exposing __dlpack__ taken in place as inputs, and DeviceArray exported to
// consumers such as cupy.from_dlpack or torch.from_dlpack without a copy.
//
// Consumer side: x.__dlpack__() hands over a capsule named "dltensor" holding a DLManagedTensor; the
// consumer renames it "used_dltensor" (so the capsule's own destructor leaves the tensor alone), reads
// the memory while it needs it, then calls the tensor's deleter once. A CUDA producer is handed the
// stream the consumer reads on (the legacy default stream, 1, which the engine then waits for).
// Producer side: the capsule's destructor calls the deleter only while the capsule is unconsumed.
#include <string>

#include "device_memory.hpp"
#include "python/module.hpp"

namespace cg::python {

namespace {

std::string device_name(int type) {
  switch (type) {
    case kDLCPU:
      return "the CPU";
    case kDLCUDA:
      return "CUDA";
    case kDLCUDAHost:
      return "CUDA pinned host memory";
    case kDLCUDAManaged:
      return "CUDA managed memory";
    default:
      return "device type " + std::to_string(type);
  }
}

// The producer's deleter, called once with the GIL held (producers release Python objects there).
void release_tensor(const DLManagedTensor* m) {
  if (!m || !m->deleter) return;
  const PyGILState_STATE gil = PyGILState_Ensure();
  m->deleter(const_cast<DLManagedTensor*>(m));
  PyGILState_Release(gil);
}

}  // namespace

std::optional<int> dlpack_device_type(const py::handle& x) {
  if (py::isinstance<py::array>(x) || !py::hasattr(x, "__dlpack__") || !py::hasattr(x, "__dlpack_device__"))
    return std::nullopt;
  const py::object device = x.attr("__dlpack_device__")();
  try {
    return py::tuple(device)[0].cast<int>();
  } catch (const py::cast_error&) {
    throw py::value_error("__dlpack_device__() returned " + py::repr(device).cast<std::string>() +
                          ", not (device type, device id)");
  }
}

DLPackHold take_dlpack(const py::object& x, const char* name, bool cuda) {
  // CUDA: the consumer's stream; the producer orders its pending work on x before it.
  const py::object capsule = cuda ? x.attr("__dlpack__")(py::arg("stream") = 1) : x.attr("__dlpack__")();
  PyObject* c = capsule.ptr();
  if (!PyCapsule_IsValid(c, "dltensor"))
    throw py::value_error(std::string(name) +
                          ": __dlpack__() returned no unused \"dltensor\" capsule (DLPack protocol)");
  auto* managed = static_cast<DLManagedTensor*>(PyCapsule_GetPointer(c, "dltensor"));
  if (!managed) throw py::error_already_set();
  DLPackHold hold(managed, release_tensor);  // from here on the deleter runs once, whatever follows
  if (PyCapsule_SetName(c, "used_dltensor") != 0) throw py::error_already_set();
  return hold;
}

py::array dlpack_host_array(const py::object& x, const char* name) {
  DLPackHold hold = take_dlpack(x, name, false);
  const DLTensor& t = hold->dl_tensor;
  if (t.device.device_type != kDLCPU)
    throw py::value_error(std::string(name) + ": __dlpack_device__ said the CPU, the tensor says " +
                          device_name(t.device.device_type));
  const int bits = t.dtype.bits;
  char kind = 0;
  if (t.dtype.code == kDLFloat && (bits == 16 || bits == 32 || bits == 64)) kind = 'f';
  if (t.dtype.code == kDLInt && (bits == 8 || bits == 16 || bits == 32 || bits == 64)) kind = 'i';
  if (t.dtype.code == kDLUInt && (bits == 8 || bits == 16 || bits == 32 || bits == 64)) kind = 'u';
  if (!kind || t.dtype.lanes != 1)
    throw py::value_error(std::string(name) + ": DLPack dtype (code " + std::to_string(t.dtype.code) + ", " +
                          std::to_string(bits) + " bits, " + std::to_string(t.dtype.lanes) +
                          " lanes) is not a number type");
  const py::dtype dtype(std::string(1, kind) + std::to_string(bits / 8));
  std::vector<py::ssize_t> shape(t.shape, t.shape + t.ndim), strides(std::size_t(t.ndim));
  py::ssize_t step = bits / 8;  // C order when the tensor gives no strides
  for (int k = t.ndim - 1; k >= 0; --k) {
    strides[k] = t.strides ? py::ssize_t(t.strides[k]) * (bits / 8) : step;
    step *= shape[k];
  }
  const char* data = static_cast<const char*>(t.data) + t.byte_offset;
  const py::capsule owner(new DLPackHold(std::move(hold)),
                          [](void* p) { delete static_cast<DLPackHold*>(p); });
  return py::array(dtype, shape, strides, data, owner);
}

// ---- DeviceArray as a DLPack producer --------------------------------------------------------------

namespace {

// What an exported tensor carries: the DLManagedTensor, its shape, and the DeviceArray it views.
struct Exported {
  DLManagedTensor managed{};
  std::vector<std::int64_t> shape;
  py::object array;  // keeps the DeviceArray (and its owner: contacts, engine) alive
};

void delete_exported(DLManagedTensor* m) {
  const PyGILState_STATE gil = PyGILState_Ensure();
  delete static_cast<Exported*>(m->manager_ctx);
  PyGILState_Release(gil);
}

// The capsule's destructor: an unconsumed capsule still owns its tensor.
void destroy_capsule(PyObject* capsule) {
  if (!PyCapsule_IsValid(capsule, "dltensor")) return;  // consumed: the consumer calls the deleter
  PyObject *type = nullptr, *value = nullptr, *trace = nullptr;
  PyErr_Fetch(&type, &value, &trace);
  auto* m = static_cast<DLManagedTensor*>(PyCapsule_GetPointer(capsule, "dltensor"));
  if (m && m->deleter) m->deleter(m);
  PyErr_Restore(type, value, trace);
}

DLDataType dl_type_of(const py::dtype& dtype) {
  DLDataType t{};
  t.bits = std::uint8_t(dtype.itemsize() * 8);
  t.lanes = 1;
  switch (dtype.kind()) {
    case 'f':
      t.code = kDLFloat;
      break;
    case 'i':
      t.code = kDLInt;
      break;
    case 'u':
      t.code = kDLUInt;
      break;
    default:
      throw py::buffer_error("__dlpack__: dtype " + py::repr(dtype).cast<std::string>() +
                             " has no DLPack type here");
  }
  return t;
}

}  // namespace

py::tuple DeviceArray::dlpack_device() const {
  return py::make_tuple(int(kDLCUDA), device_memory::device_of(reinterpret_cast<const void*>(m_pointer)));
}

py::capsule DeviceArray::dlpack(const py::object& self, const py::object& stream, const py::object&,
                                const py::object& dl_device, const py::object& copy) {
  const DeviceArray& a = self.cast<const DeviceArray&>();
  if (a.m_owner && py::hasattr(a.m_owner, "_check_current")) a.m_owner.attr("_check_current")();
  if (!stream.is_none() && !py::isinstance<py::int_>(stream))
    throw py::type_error("__dlpack__: stream must be None or an int (a CUDA stream)");
  // The memory is complete when exposed (the engine returns after its results are), so the consumer's
  // stream needs no wait.
  const py::tuple here = a.dlpack_device();
  if (!dl_device.is_none() && !py::tuple(dl_device).equal(here))
    throw py::buffer_error("__dlpack__: the array lives on " + py::repr(here).cast<std::string>() +
                           ", asked for " + py::repr(dl_device).cast<std::string>() + " (no copies made)");
  if (!copy.is_none() && copy.cast<bool>())
    throw py::buffer_error(
        "__dlpack__: copy=True is not supported (DeviceArray exports its memory in place)");

  auto* e = new Exported;
  e->shape.assign(a.m_shape.begin(), a.m_shape.end());
  e->array = self;
  DLTensor& t = e->managed.dl_tensor;
  try {
    t.dtype = dl_type_of(a.m_dtype);
  } catch (...) {
    delete e;
    throw;
  }
  t.data = reinterpret_cast<void*>(a.m_pointer);
  t.device = {kDLCUDA, here[1].cast<int>()};
  t.ndim = int(e->shape.size());
  t.shape = e->shape.data();
  t.strides = nullptr;  // C order
  t.byte_offset = 0;
  e->managed.manager_ctx = e;
  e->managed.deleter = delete_exported;
  PyObject* capsule = PyCapsule_New(&e->managed, "dltensor", destroy_capsule);
  if (!capsule) {
    delete e;
    throw py::error_already_set();
  }
  return py::reinterpret_steal<py::capsule>(capsule);
}

}  // namespace cg::python
