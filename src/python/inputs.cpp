// Python arrays → the engine's views (module.hpp: HostBodies, DeviceBodies).
#include <algorithm>
#include <cstring>
#include <string>

#include "device_memory.hpp"
#include "python/module.hpp"

namespace cg::python {

static_assert(sizeof(Vec3<double>) == 3 * sizeof(double) && alignof(Vec3<double>) == alignof(double),
              "an (N, 3) float64 array is read as N Vec3<double>");
static_assert(sizeof(Quat<double>) == 4 * sizeof(double),
              "an (N, 4) float64 array is read as N Quat<double>");

namespace {

std::string shape_text(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t k = 0; k < a.ndim(); ++k) s += (k ? ", " : "") + std::to_string(a.shape(k));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

// `x` as float64 in C order: the array itself when it is one already, else one converted copy.
Doubles as_doubles(const py::object& x, const char* name) {
  py::array a;
  if (const std::optional<int> device = dlpack_device_type(x)) {  // DLPack: CPU tensors in place
    if (*device == kDLCUDA || *device == kDLCUDAManaged)
      throw py::value_error(std::string(name) +
                            ": a GPU array (DLPack) where the other arrays are in host memory: pass all on "
                            "one side (GPU arrays: positions and radii of spheres)");
    if (*device != kDLCPU)
      throw py::value_error(std::string(name) + ": DLPack device type " + std::to_string(*device) +
                            " is neither the CPU (1) nor CUDA (2)");
    a = dlpack_host_array(x, name);
  } else {
    try {
      a = py::array::ensure(x);
    } catch (const py::error_already_set&) {
    }
  }
  if (!a) throw py::value_error(std::string(name) + ": not an array of numbers");
  if (a.dtype().kind() != 'f' && a.dtype().kind() != 'i' && a.dtype().kind() != 'u')
    throw py::value_error(std::string(name) + ": dtype " + py::str(a.dtype()).cast<std::string>() +
                          " is not a number type");
  return Doubles::ensure(a);  // no copy for float64 C order
}

std::string number_text(double v) { return py::repr(py::float_(v)).cast<std::string>(); }

}  // namespace

Doubles float64_rows(const py::object& x, const char* name, py::ssize_t columns,
                     std::optional<std::size_t> n) {
  Doubles a = as_doubles(x, name);
  if (a.ndim() != 2 || a.shape(1) != columns || (n && std::size_t(a.shape(0)) != *n))
    throw py::value_error(std::string(name) + ": shape " + shape_text(a) + ", expected (" +
                          (n ? std::to_string(*n) : std::string("N")) + ", " + std::to_string(columns) + ")");
  return a;
}

HostBodies::HostBodies(const py::object& positions, const py::object& radii, const py::object& semi_axes,
                       const py::object& orientations) {
  m_position = float64_rows(positions, "positions", 3, std::nullopt);
  m_count = std::size_t(m_position.shape(0));
  const std::size_t n = m_count;
  if (!radii.is_none()) {
    py::array r = as_doubles(radii, "radii");
    if (r.ndim() == 0) {  // one radius for every body
      m_radius_made.assign(n, Doubles::ensure(r).at());
    } else if (r.ndim() != 1 || std::size_t(r.shape(0)) != n) {
      throw py::value_error("radii: shape " + shape_text(r) + ", expected (" + std::to_string(n) +
                            ",) like positions (or one number)");
    } else {
      m_radius = Doubles::ensure(r);
      m_radius_given = true;
    }
  }
  if (semi_axes.is_none()) {
    if (!orientations.is_none()) throw py::value_error("orientations: given without semi_axes");
    if (radii.is_none()) throw py::value_error("radii: required for spheres (no semi_axes given)");
    return;
  }
  m_semi_axes = float64_rows(semi_axes, "semi_axes", 3, n);
  if (!orientations.is_none()) {
    m_orientation = float64_rows(orientations, "orientations", 4, n);
    m_orientation_given = true;
  } else {
    m_identity.assign(n, Quat<double>{1, 0, 0, 0});
  }
  // Kinds: equal semi-axes make a sphere. The bounding radius is the largest semi-axis; radii, when
  // given, must be exactly that (the engine's shape check says the same for ellipsoids).
  const Vec3<double>* axes = reinterpret_cast<const Vec3<double>*>(m_semi_axes.data());
  m_shape.resize(n);
  const double* given =
      m_radius_given ? m_radius.data() : (m_radius_made.empty() ? nullptr : m_radius_made.data());
  std::vector<double> bounding(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3<double> s = axes[i];
    m_shape[i] = s.x == s.y && s.y == s.z ? Shape::sphere : Shape::ellipsoid;
    bounding[i] = std::max({s.x, s.y, s.z});
    if (given && given[i] != bounding[i])
      throw py::value_error("radii: body " + std::to_string(i) + " has radius " + number_text(given[i]) +
                            " but largest semi-axis " + number_text(bounding[i]) +
                            " (with semi_axes, leave radii None)");
  }
  if (!given) m_radius_made = std::move(bounding);
}

BodiesView HostBodies::view() const {
  const std::size_t n = m_count;
  BodiesView v;
  v.position = {reinterpret_cast<const Vec3<double>*>(m_position.data()), n};
  v.radius = {m_radius_given ? m_radius.data() : m_radius_made.data(), n};
  if (!m_shape.empty()) {
    v.shape = {m_shape.data(), n};
    v.semi_axes = {reinterpret_cast<const Vec3<double>*>(m_semi_axes.data()), n};
    v.orientation =
        m_orientation_given
            ? std::span<const Quat<double>>{reinterpret_cast<const Quat<double>*>(m_orientation.data()), n}
            : std::span<const Quat<double>>{m_identity.data(), n};
  }
  return v;
}

// ---- GPU arrays: __cuda_array_interface__ and DLPack -----------------------------------------------

namespace {
bool has_cai(const py::handle& x) { return py::hasattr(x, "__cuda_array_interface__"); }
bool cuda_dlpack(const py::handle& x) {
  const std::optional<int> device = dlpack_device_type(x);
  return device && (*device == kDLCUDA || *device == kDLCUDAManaged);
}
}  // namespace

bool is_device_array(const py::handle& x) { return has_cai(x) || cuda_dlpack(x); }

namespace {

struct DeviceInput {
  std::uintptr_t pointer = 0;
  std::vector<std::size_t> shape;
  std::uintptr_t stream = 0;
  DLPackHold hold;  // DLPack: the tensor, held while the engine reads
};

std::string shape_wanted(std::size_t columns) {
  return columns ? "(N, " + std::to_string(columns) + ")" : "(N,)";
}

// A CUDA DLPack tensor: float64, C order (strides NULL or compact), `columns` columns (0: one dimension).
DeviceInput dlpack_input(const py::object& x, const char* name, std::size_t columns) {
  DeviceInput in;
  in.hold = take_dlpack(x, name, true);
  in.stream = 1;  // handed to __dlpack__: the producer's work is ordered before it
  const DLTensor& t = in.hold->dl_tensor;
  if (t.device.device_type != kDLCUDA && t.device.device_type != kDLCUDAManaged)
    throw py::value_error(std::string(name) + ": __dlpack_device__ said CUDA, the tensor says device type " +
                          std::to_string(t.device.device_type));
  if (t.dtype.code != kDLFloat || t.dtype.bits != 64 || t.dtype.lanes != 1)
    throw py::value_error(std::string(name) +
                          ": GPU arrays are read in place and must be float64 (DLPack dtype code " +
                          std::to_string(t.dtype.code) + ", " + std::to_string(t.dtype.bits) + " bits, " +
                          std::to_string(t.dtype.lanes) + " lanes)");
  const int dims = columns ? 2 : 1;
  for (int k = 0; k < t.ndim; ++k) in.shape.push_back(std::size_t(t.shape[k]));
  if (t.ndim != dims || (columns && in.shape[1] != columns))
    throw py::value_error(std::string(name) + ": GPU array of " + std::to_string(t.ndim) +
                          " dimensions, expected " + shape_wanted(columns));
  if (t.strides) {  // compact C order; the stride of a dimension of length 1 does not matter
    std::int64_t step = 1;
    for (int k = dims - 1; k >= 0; --k) {
      if (t.shape[k] > 1 && t.strides[k] != step)
        throw py::value_error(std::string(name) + ": GPU arrays are read in place and must be C-contiguous");
      step *= t.shape[k];
    }
  }
  in.pointer = reinterpret_cast<std::uintptr_t>(static_cast<const char*>(t.data) + t.byte_offset);
  return in;
}

// __cuda_array_interface__ (v2 or v3): float64, C order, `columns` columns (0: one dimension).
DeviceInput cai_input(const py::object& x, const char* name, std::size_t columns) {
  const py::dict cai = x.attr("__cuda_array_interface__");
  const std::string typestr = py::str(cai["typestr"]);
  if (typestr != "<f8")
    throw py::value_error(std::string(name) +
                          ": GPU arrays are read in place and must be float64 ('<f8'), "
                          "not '" +
                          typestr + "'");
  DeviceInput in;
  for (const auto& k : py::tuple(cai["shape"])) in.shape.push_back(k.cast<std::size_t>());
  const std::size_t dims = columns ? 2 : 1;
  if (in.shape.size() != dims || (columns && in.shape[1] != columns))
    throw py::value_error(std::string(name) + ": GPU array of " + std::to_string(in.shape.size()) +
                          " dimensions, expected " + shape_wanted(columns));
  if (cai.contains("strides") && !cai["strides"].is_none()) {
    const py::tuple strides = cai["strides"];
    const std::size_t row = 8 * (columns ? columns : 1);
    bool c_order = strides.size() == dims && strides[0].cast<std::size_t>() == row;
    if (columns && c_order) c_order = strides[1].cast<std::size_t>() == 8;
    if (!c_order && in.shape[0] > 1)
      throw py::value_error(std::string(name) + ": GPU arrays are read in place and must be C-contiguous");
  }
  if (cai.contains("mask") && !cai["mask"].is_none())
    throw py::value_error(std::string(name) + ": masked GPU arrays are not supported");
  const py::tuple data = cai["data"];
  in.pointer = data[0].cast<std::uintptr_t>();
  if (cai.contains("stream") && !cai["stream"].is_none()) in.stream = cai["stream"].cast<std::uintptr_t>();
  return in;
}

// The float64 C-order device array `x` exposes, with `columns` columns (0: one dimension).
DeviceInput device_input(const py::object& x, const char* name, std::size_t columns) {
  if (!is_device_array(x))
    throw py::value_error(std::string(name) +
                          ": a NumPy array where the other arrays are on the GPU "
                          "(__cuda_array_interface__ or DLPack): pass all on one side");
  DeviceInput in = has_cai(x) ? cai_input(x, name, columns) : dlpack_input(x, name, columns);
  if (in.pointer && !device_memory::is_device_pointer(reinterpret_cast<const void*>(in.pointer)))
    throw py::value_error(std::string(name) + ": " +
                          (in.hold ? "the DLPack tensor" : "__cuda_array_interface__") +
                          " points to memory the GPU cannot read as device memory");
  return in;
}

}  // namespace

DeviceBodies::DeviceBodies(const py::object& positions, const py::object& radii, const py::object& semi_axes,
                           const py::object& orientations) {
  if (!semi_axes.is_none() || !orientations.is_none())
    throw py::value_error(
        "semi_axes, orientations: GPU arrays are read for spheres only; pass scenes with "
        "ellipsoids as NumPy arrays");
  if (radii.is_none()) throw py::value_error("radii: required for spheres (no semi_axes given)");
  const DeviceInput p = device_input(positions, "positions", 3), r = device_input(radii, "radii", 0);
  if (r.shape[0] != p.shape[0])
    throw py::value_error("radii: " + std::to_string(r.shape[0]) + " rows, positions " +
                          std::to_string(p.shape[0]));
  m_view.position = reinterpret_cast<const double*>(p.pointer);
  m_view.radius = reinterpret_cast<const double*>(r.pointer);
  m_view.count = p.shape[0];
  for (std::uintptr_t s : {p.stream, r.stream})
    if (s && std::find(m_streams.begin(), m_streams.end(), s) == m_streams.end()) m_streams.push_back(s);
  for (const DLPackHold& h : {p.hold, r.hold})
    if (h) m_held.push_back(h);
}

void DeviceBodies::synchronize() const {
  for (std::uintptr_t s : m_streams) device_memory::synchronize_stream(s);
}

}  // namespace cg::python
