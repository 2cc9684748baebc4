// contactgrid.Contacts and contactgrid.DeviceArray (module.hpp: PyContacts, DeviceArray): the engine's
// result as NumPy arrays over its own storage, or as __cuda_array_interface__ objects on the GPU.
#include <type_traits>

#include "device_memory.hpp"
#include "io/contact_file.hpp"
#include "python/module.hpp"

namespace cg::python {

namespace {

template <class T>
struct is_vec3 : std::false_type {};
template <class R>
struct is_vec3<Vec3<R>> : std::true_type {};

// The element type and the columns of a field whose rows are T: Vec3<R> is three R's.
template <class T>
struct Layout {
  using Scalar = T;
  static constexpr py::ssize_t columns = 0;
};
template <class R>
struct Layout<Vec3<R>> {
  using Scalar = R;
  static constexpr py::ssize_t columns = 3;
};

template <class T>
std::vector<py::ssize_t> shape_of(std::size_t rows) {
  if (Layout<T>::columns) return {py::ssize_t(rows), Layout<T>::columns};
  return {py::ssize_t(rows)};
}

// A NumPy array over `rows` rows of T at `data` (host memory `owner` keeps alive).
template <class T>
py::array host_column(const T* data, std::size_t rows, const py::object& owner) {
  using S = typename Layout<T>::Scalar;
  const std::vector<py::ssize_t> shape = shape_of<T>(rows);
  if (rows == 0) return py::array_t<S>(shape);
  std::vector<py::ssize_t> strides{py::ssize_t(sizeof(T))};
  if (Layout<T>::columns) strides.push_back(sizeof(S));
  return py::array_t<S>(shape, strides, reinterpret_cast<const S*>(data), owner);
}

// f(field index, column) for the field called `name`, when present.
template <class Columns, class F>
bool with_field(Columns& columns, FieldSet set, const std::string& name, F&& f) {
  bool found = false;
  for_each_contact_field(columns, set, [&](auto index, auto& column) {
    if (!found && name == kContactFields[index].name()) {
      found = true;
      f(index, column);
    }
  });
  return found;
}

template <class Real>
std::size_t rows_of(const Contacts<Real>& c) {
  return c.size();
}
template <class Real>
std::size_t rows_of(const DeviceContactsView<Real>& c) {
  return c.count;
}

}  // namespace

std::size_t PyContacts::size() const {
  if (on_device()) {
    return std::visit(
        [](const auto& v) -> std::size_t {
          if constexpr (std::is_same_v<std::decay_t<decltype(v)>, std::monostate>)
            return 0;
          else
            return rows_of(v);
        },
        m_device);
  }
  return std::visit(
      [](const auto& c) -> std::size_t {
        if constexpr (std::is_same_v<std::decay_t<decltype(c)>, std::monostate>)
          return 0;
        else
          return rows_of(c);
      },
      m_host);
}

FieldSet PyContacts::fields() const {
  FieldSet set;
  auto get = [&](const auto& c) {
    if constexpr (!std::is_same_v<std::decay_t<decltype(c)>, std::monostate>) set = c.fields();
  };
  std::visit(get, m_host);
  std::visit(get, m_device);
  return set;
}

std::vector<std::string> PyContacts::names() const {
  std::vector<std::string> out;
  const FieldSet set = fields();
  for (const ContactField& f : kContactFields)
    if (set.has(f.group)) out.emplace_back(f.name());
  return out;
}

void PyContacts::check_current() const {
  if (on_device() && *m_generation != m_made_at)
    throw py::value_error(
        "these device contacts were overwritten: their engine has detected again since (copy them first, "
        "e.g. contacts.to_host(), or use one Engine per result you keep)");
}

py::object PyContacts::field(const py::object& self, const std::string& name) const {
  check_current();
  py::object out;
  const FieldSet set = fields();
  auto host = [&](const auto& c) {
    if constexpr (!std::is_same_v<std::decay_t<decltype(c)>, std::monostate>) {
      with_field(c, set, name, [&](auto, const auto& column) {
        using T = typename std::decay_t<decltype(column)>::value_type;
        out = host_column<T>(column.data(), column.size(), self);
      });
    }
  };
  auto device = [&](const auto& v) {
    if constexpr (!std::is_same_v<std::decay_t<decltype(v)>, std::monostate>) {
      with_field(v, set, name, [&](auto, const auto& column) {
        using T = std::remove_cv_t<std::remove_pointer_t<std::decay_t<decltype(column)>>>;
        using S = typename Layout<T>::Scalar;
        out = py::cast(std::make_unique<DeviceArray>(reinterpret_cast<std::uintptr_t>(column),
                                                     shape_of<T>(v.count), py::dtype::of<S>(), self));
      });
    }
  };
  std::visit(host, m_host);
  std::visit(device, m_device);
  if (!out) {
    for (const ContactField& f : kContactFields)
      if (name == f.name())
        throw py::key_error("'" + name + "': an optional field, computed with " +
                            (f.group == FieldGroup::history ? "Engine(history=True)" : "fields='full'") +
                            " only");
    throw py::key_error("'" + name + "': not a contact field");
  }
  return out;
}

py::object PyContacts::to_host(const py::object& self) const {
  check_current();
  if (!on_device()) return self;
  return std::visit(
      [&](const auto& v) -> py::object {
        if constexpr (std::is_same_v<std::decay_t<decltype(v)>, std::monostate>) {
          return self;
        } else {
          using Real = std::decay_t<decltype(v.distance[0])>;
          Contacts<Real> c;
          {
            py::gil_scoped_release release;
            c.resize(v.count, v.fields());
            zip_contact_fields(c, v, v.fields(), [&](auto, auto& host, const auto* device) {
              device_memory::copy_to_host(host.data(), device, host.size() * sizeof(host[0]));
            });
          }
          return py::cast(PyContacts(std::move(c), m_record));
        }
      },
      m_device);
}

void PyContacts::write(const std::string& path) const {
  if (on_device()) throw py::value_error("write_contacts: device contacts; call contacts.to_host() first");
  RunInfo info;
  info.bodies = m_record.bodies;
  info.precision = to_string(m_record.precision);
  info.precision_choice = m_record.precision_reason;
  info.backend = to_string(m_record.backend);
  info.cell_size = m_record.stats.cell_size;
  info.input = "(python)";
  info.times = m_record.times;
  info.ellipsoids = m_record.stats.ellipsoids;
  info.narrow_fallbacks = m_record.stats.narrow_fallbacks;
  info.narrow_unconverged = m_record.stats.narrow_unconverged;
  std::visit(
      [&](const auto& c) {
        if constexpr (!std::is_same_v<std::decay_t<decltype(c)>, std::monostate>) {
          py::gil_scoped_release release;
          write_contacts(path, c, info);
        }
      },
      m_host);
}

// ---- DeviceArray ------------------------------------------------------------------------------------

DeviceArray::DeviceArray(const py::array& host) {
  const py::array a = py::array::ensure(host, py::array::c_style);
  if (!a) throw py::value_error("DeviceArray: not an array");
  m_dtype = a.dtype();
  for (py::ssize_t k = 0; k < a.ndim(); ++k) m_shape.push_back(a.shape(k));
  const std::size_t bytes = std::size_t(a.nbytes());
  void* p = device_memory::allocate(bytes);
  m_pointer = reinterpret_cast<std::uintptr_t>(p);
  m_owned = true;
  try {
    device_memory::copy_to_device(p, a.data(), bytes);
  } catch (...) {
    device_memory::release(p);
    m_owned = false;
    throw;
  }
}

DeviceArray::DeviceArray(std::uintptr_t pointer, std::vector<py::ssize_t> shape, py::dtype dtype,
                         py::object owner)
    : m_pointer(pointer), m_shape(std::move(shape)), m_dtype(std::move(dtype)), m_owner(std::move(owner)) {}

DeviceArray::~DeviceArray() {
  if (m_owned) device_memory::release(reinterpret_cast<void*>(m_pointer));
}

py::dict DeviceArray::interface() const {
  if (m_owner && py::hasattr(m_owner, "_check_current")) m_owner.attr("_check_current")();
  py::dict d;
  py::tuple shape(m_shape.size());
  for (std::size_t k = 0; k < m_shape.size(); ++k) shape[k] = py::int_(m_shape[k]);
  d["shape"] = shape;
  d["typestr"] = m_dtype.attr("str");
  d["data"] = py::make_tuple(py::int_(m_pointer), false);
  d["version"] = 3;
  d["strides"] = py::none();  // C order
  d["stream"] = py::none();   // complete when exposed: the engine returns after its results are
  return d;
}

py::array DeviceArray::copy_to_host() const {
  if (m_owner && py::hasattr(m_owner, "_check_current")) m_owner.attr("_check_current")();
  py::array out(m_dtype, m_shape);
  const std::size_t bytes = std::size_t(out.nbytes());
  void* dst = out.mutable_data();
  {
    py::gil_scoped_release release;
    device_memory::copy_to_host(dst, reinterpret_cast<const void*>(m_pointer), bytes);
  }
  return out;
}

// ---- dicts -----------------------------------------------------------------------------------------

py::dict stats_dict(const EngineStats& s) {
  py::dict d;
  d["bodies"] = s.bodies;
  d["entries"] = s.entries;
  d["pair_tests"] = s.pair_tests;
  d["candidates"] = s.candidates;
  d["contacts"] = s.contacts;
  d["key_bits"] = s.key_bits;
  d["cell_size"] = s.cell_size;
  d["peak_device_bytes"] = s.peak_device_bytes;
  d["device_allocations"] = s.device_allocations;
  d["ellipsoids"] = s.ellipsoids;
  d["narrow_fallbacks"] = s.narrow_fallbacks;
  d["narrow_unconverged"] = s.narrow_unconverged;
  d["narrow_unsettled"] = s.narrow_unsettled;
  d["narrow_hard"] = s.narrow_hard;
  d["fp64_rows"] = s.fp64_rows;
  d["candidate_builds"] = s.candidate_builds;
  d["candidate_reuses"] = s.candidate_reuses;
  d["skin_displacement"] = s.skin_displacement;
  d["skin_growth"] = s.skin_growth;
  return d;
}

py::dict times_dict(const StageTimes& times) {
  py::dict d;
  for (const StageTime& t : times) {
    const py::str key(t.name);
    d[key] = d.contains(key) ? d[key].cast<double>() + t.seconds : t.seconds;
  }
  return d;
}

}  // namespace cg::python
