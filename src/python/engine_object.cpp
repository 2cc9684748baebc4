// contactgrid.Engine (module.hpp: PyEngine): the options as words, the precision mode, the engine kept
// between calls; every engine call with the GIL released.
#include <cmath>
#include <cstdlib>
#include <string>
#include <string_view>

#include "device_memory.hpp"
#include "python/module.hpp"

namespace cg::python {

Backend backend_of(const std::string& word) {
  if (word == "auto") return Backend::automatic;
  if (word == "cpu") return Backend::cpu;
  if (word == "cuda") return Backend::cuda;
  throw py::value_error("backend: '" + word + "' is not auto, cpu or cuda");
}

std::optional<Precision> precision_of_word(const std::string& word) {
  if (word == "auto") return std::nullopt;
  if (word == "fp32") return Precision::fp32;
  if (word == "fp64") return Precision::fp64;
  if (word == "mixed") return Precision::mixed;
  throw py::value_error("precision: '" + word + "' is not auto, fp32, fp64 or mixed");
}

Fields fields_of(const std::string& word) {
  if (word == "basic") return Fields::basic;
  if (word == "full") return Fields::full;
  throw py::value_error("fields: '" + word + "' is not basic or full");
}

Accuracy accuracy_of(const py::object& accuracy) {
  Accuracy a;
  if (accuracy.is_none()) return a;
  auto number = [](const py::handle& x, const char* what) {
    double v = 0;
    try {
      v = x.cast<double>();
    } catch (const py::cast_error&) {
      throw py::value_error(std::string("accuracy: ") + what + " is not a number");
    }
    if (!(v > 0) || !std::isfinite(v))
      throw py::value_error(std::string("accuracy: ") + what + " " + py::repr(x).cast<std::string>() +
                            " is not a number > 0");
    return v;
  };
  if (py::isinstance<py::tuple>(accuracy) || py::isinstance<py::list>(accuracy)) {
    const py::sequence s = accuracy;
    if (s.size() != 2) throw py::value_error("accuracy: a number or a pair (position, angle in degrees)");
    a.position = number(s[0], "the position error (relative to the smallest radius)");
    a.angle_deg = number(s[1], "the normal angle (degrees)");
  } else {
    a.position = number(accuracy, "the position error (relative to the smallest radius)");
  }
  return a;
}

PyEngine::PyEngine(const std::string& backend, const std::string& precision, const py::object& accuracy,
                   const std::string& fields, int threads, double skin, int device, bool history) {
  m_options.backend = backend_of(backend);
  m_fixed = precision_of_word(precision);
  m_accuracy = accuracy_of(accuracy);
  m_options.fields = fields_of(fields);
  if (threads < 0) throw py::value_error("threads: must be >= 0 (0: all cores)");
  m_options.threads = threads;
  if (!(skin >= 0) || !std::isfinite(skin)) throw py::value_error("skin: must be a finite length >= 0");
  m_options.skin = skin;
  m_options.device = device;
  m_options.history = history;
  if (m_fixed && m_accuracy.position)
    throw py::value_error(std::string("accuracy: only with precision 'auto' (the default), not precision '") +
                          to_string(*m_fixed) + "'");
  m_backend = m_options.backend;
  if (m_backend == Backend::automatic) m_backend = cuda_available() ? Backend::cuda : Backend::cpu;
  m_options.backend = m_backend;
  if (m_fixed) make(std::nullopt, false);
}

void PyEngine::make(const std::optional<Bounds>& bounds, bool ellipsoids) {
  if (m_mode) return;
  Precision mode = Precision::fp64;
  if (m_fixed) {
    mode = *m_fixed;
  } else {
    const PrecisionChoice c =
        choose_precision(precision_scene(*bounds, ellipsoids, m_options.cell_size, m_options.cell_choice),
                         m_backend, m_accuracy);
    mode = c.mode;
    m_reason = c.reason;
  }
  EngineOptions o = m_options;
  o.fp32_broad_phase = mode == Precision::mixed;
  if (mode == Precision::fp32)
    m_engine = std::make_unique<Engine<float>>(o);
  else
    m_engine = std::make_unique<Engine<double>>(o);
  m_mode = mode;
}

// f(engine) on the engine of the chosen mode (made before).
template <class F>
auto PyEngine::with_engine(F&& f) {
  if (auto* e = std::get_if<std::unique_ptr<Engine<float>>>(&m_engine)) return f(**e);
  return f(*std::get<std::unique_ptr<Engine<double>>>(m_engine));
}

RunRecord PyEngine::record(std::uint64_t bodies) const {
  RunRecord r;
  r.precision = m_mode.value_or(Precision::fp64);
  r.precision_reason = m_reason;
  r.backend = m_backend;
  r.bodies = bodies;
  std::visit(
      [&](const auto& e) {
        if constexpr (!std::is_same_v<std::decay_t<decltype(e)>, std::monostate>) {
          r.times = e->times();
          r.stats = e->stats();
        }
      },
      m_engine);
  return r;
}

namespace {
// The mode `auto` chooses from: the bounds and whether any body is an ellipsoid.
struct SceneSummary {
  Bounds bounds;
  bool ellipsoids = false;
};
// CONTACTGRID_AUTO_BOUNDS=engine: the engine computes the bounds again rather than take those precision
// "auto" chose from (a measurement switch: the former path, the same contacts).
bool engine_bounds_again() {
  const char* v = std::getenv("CONTACTGRID_AUTO_BOUNDS");
  return v != nullptr && std::string_view(v) == "engine";
}
SceneSummary summarise(const HostBodies& bodies) {
  const BodiesView v = bodies.view();
  SceneSummary s;
  s.bounds = compute_bounds(v);
  s.ellipsoids = bodies.has_shapes() && validate_shapes(v) > 0;
  return s;
}
}  // namespace

py::object PyEngine::detect(const py::object& self, const py::object& positions, const py::object& radii,
                            const py::object& semi_axes, const py::object& orientations) {
  if (is_device_array(positions) || (!radii.is_none() && is_device_array(radii))) {
    const DeviceBodies bodies(positions, radii, semi_axes, orientations);
    std::variant<DeviceContactsView<float>, DeviceContactsView<double>> view;
    RunRecord rec;
    {
      py::gil_scoped_release release;
      std::lock_guard lock(m_mutex);
      if (m_backend != Backend::cuda)
        throw UsageError(
            "GPU arrays need the CUDA backend (backend 'cuda', or 'auto' where a GPU is present)");
      bodies.synchronize();
      if (!m_mode) {  // auto: the bounds from the device, the mode from them
        EngineOptions o = m_options;
        auto probe = std::make_unique<Engine<double>>(o);
        std::size_t ellipsoids = 0;
        const Bounds b = probe->device_bounds(bodies.view(), &ellipsoids);
        if (b.count == 0) throw UsageError("detect: no bodies (precision 'auto' chooses from the bodies)");
        make(b, ellipsoids > 0);
      }
      bump();
      with_engine([&](auto& e) { view = e.detect_device_resident(bodies.view()); });
      rec = record(bodies.view().count);
    }
    return std::visit(
        [&](const auto& v) { return py::cast(PyContacts(v, std::move(rec), self, m_generation)); }, view);
  }

  const HostBodies bodies(positions, radii, semi_axes, orientations);
  std::variant<Contacts<float>, Contacts<double>> out;
  RunRecord rec;
  {
    py::gil_scoped_release release;
    std::lock_guard lock(m_mutex);
    if (!m_mode && bodies.size() == 0) {  // auto and nothing to choose from: no contacts, fp64
      rec = record(0);
      std::get<Contacts<float>>(out).resize(0, FieldSet{m_options.fields == Fields::full, m_options.history});
    } else {
      std::optional<Bounds> bounds;  // auto: the mode's bounds, which the engine then takes as its own
      if (!m_mode) {
        const SceneSummary s = summarise(bodies);
        make(s.bounds, s.ellipsoids);
        if (!engine_bounds_again()) bounds = s.bounds;
      }
      bump();
      with_engine(
          [&](auto& e) { out = bounds ? e.detect(bodies.view(), *bounds) : e.detect(bodies.view()); });
      rec = record(bodies.size());
    }
  }
  return std::visit([&](auto& c) { return py::cast(PyContacts(std::move(c), std::move(rec))); }, out);
}

namespace {
// GPU arrays (spheres) as NumPy copies: what set_resident takes its rows from.
std::pair<Doubles, Doubles> host_copies(const py::object& positions, const py::object& radii,
                                        const py::object& semi_axes, const py::object& orientations) {
  const DeviceBodies device(positions, radii, semi_axes, orientations);
  const DeviceBodiesView& v = device.view();
  Doubles p({py::ssize_t(v.count), py::ssize_t(3)}), r({py::ssize_t(v.count)});
  double *to_p = p.mutable_data(), *to_r = r.mutable_data();
  {
    py::gil_scoped_release release;
    device.synchronize();
    device_memory::copy_to_host(to_p, v.position, v.count * 3 * sizeof(double));
    device_memory::copy_to_host(to_r, v.radius, v.count * sizeof(double));
  }
  return {p, r};
}
}  // namespace

void PyEngine::set_resident(const py::object& positions, const py::object& radii, const py::object& semi_axes,
                            const py::object& orientations) {
  if (is_device_array(positions) || (!radii.is_none() && is_device_array(radii))) {
    const auto [p, r] = host_copies(positions, radii, semi_axes, orientations);
    set_resident(p, r, py::none(), py::none());
    return;
  }
  const HostBodies bodies(positions, radii, semi_axes, orientations);
  py::gil_scoped_release release;
  std::lock_guard lock(m_mutex);
  if (!m_mode) {
    if (bodies.size() == 0)
      throw UsageError("set_resident: no bodies (precision 'auto' chooses from the bodies)");
    const SceneSummary s = summarise(bodies);
    make(s.bounds, s.ellipsoids);
  }
  bump();
  with_engine([&](auto& e) { e.set_resident(bodies.view()); });
}

namespace {
void need_resident(bool made) {
  if (!made) throw UsageError("no resident bodies: call set_resident first");
}
}  // namespace

void PyEngine::write_resident(std::size_t first, const py::object& positions, const py::object& radii) {
  const HostBodies bodies(positions, radii, py::none(), py::none());
  py::gil_scoped_release release;
  std::lock_guard lock(m_mutex);
  need_resident(m_mode.has_value());
  const BodiesView v = bodies.view();
  with_engine([&](auto& e) { e.write_resident(first, v.size(), v.position.data(), v.radius.data()); });
}

void PyEngine::write_resident_shapes(std::size_t first, const py::object& semi_axes,
                                     const py::object& orientations) {
  std::optional<Doubles> axes, turns;
  std::optional<std::size_t> n;
  if (!semi_axes.is_none()) {
    axes = float64_rows(semi_axes, "semi_axes", 3, std::nullopt);
    n = std::size_t(axes->shape(0));
  }
  if (!orientations.is_none()) {
    turns = float64_rows(orientations, "orientations", 4, n);
    n = std::size_t(turns->shape(0));
  }
  if (!n) return;
  py::gil_scoped_release release;
  std::lock_guard lock(m_mutex);
  need_resident(m_mode.has_value());
  with_engine([&](auto& e) {
    e.write_resident_shapes(first, *n, axes ? reinterpret_cast<const Vec3<double>*>(axes->data()) : nullptr,
                            turns ? reinterpret_cast<const Quat<double>*>(turns->data()) : nullptr);
  });
}

py::tuple PyEngine::read_resident(std::size_t first, std::optional<std::size_t> count) {
  std::size_t n = 0;
  {
    std::lock_guard lock(m_mutex);
    need_resident(m_mode.has_value());
    n = with_engine([&](auto& e) { return e.resident_size(); });
  }
  const std::size_t k = count.value_or(first < n ? n - first : 0);
  Doubles position({py::ssize_t(k), py::ssize_t(3)}), radius({py::ssize_t(k)});
  Vec3<double>* p = reinterpret_cast<Vec3<double>*>(position.mutable_data());
  double* r = radius.mutable_data();
  {
    py::gil_scoped_release release;
    std::lock_guard lock(m_mutex);
    with_engine([&](auto& e) { e.read_resident(first, k, p, r); });
  }
  return py::make_tuple(position, radius);
}

py::object PyEngine::detect_resident(const py::object&) {
  std::variant<Contacts<float>, Contacts<double>> out;
  RunRecord rec;
  {
    py::gil_scoped_release release;
    std::lock_guard lock(m_mutex);
    need_resident(m_mode.has_value());
    bump();
    with_engine([&](auto& e) {
      e.detect_resident();
      out = e.resident_contacts();  // one copy: the engine keeps its own for the next step
    });
    rec = record(with_engine([](auto& e) { return e.resident_size(); }));
  }
  return std::visit([&](auto& c) { return py::cast(PyContacts(std::move(c), std::move(rec))); }, out);
}

std::size_t PyEngine::resident_size() {
  std::lock_guard lock(m_mutex);
  if (!m_mode) return 0;
  return with_engine([](auto& e) { return e.resident_size(); });
}

void PyEngine::reset_history() {
  py::gil_scoped_release release;
  std::lock_guard lock(m_mutex);
  if (m_mode) with_engine([](auto& e) { e.reset_history(); });
}

std::string PyEngine::backend() const { return to_string(m_backend); }

std::optional<std::string> PyEngine::precision() const {
  if (!m_mode) return std::nullopt;
  return std::string(to_string(*m_mode));
}

py::dict PyEngine::stats() {
  RunRecord r;
  {
    std::lock_guard lock(m_mutex);
    r = record(0);
  }
  return stats_dict(r.stats);
}

py::dict PyEngine::times() {
  RunRecord r;
  {
    std::lock_guard lock(m_mutex);
    r = record(0);
  }
  return times_dict(r.times);
}

}  // namespace cg::python
