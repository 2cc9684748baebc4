// read_scene, write_scene, read_contacts (module.hpp): the HDF5 files of docs/FORMAT.md §1 and §2 through the
// readers and writers the CLI uses (src/io), so the messages are the CLI's.
#include "io/contact_file.hpp"
#include "io/scene_file.hpp"
#include "python/module.hpp"

namespace cg::python {

namespace {

// A NumPy array that owns `rows` (moved into the array's capsule: no copy).
template <class T, std::size_t Columns>
py::array owned_rows(HostVector<T>&& rows) {
  using S = std::conditional_t<Columns == 0, T, double>;
  auto* held = new HostVector<T>(std::move(rows));
  py::capsule owner(held, [](void* p) { delete static_cast<HostVector<T>*>(p); });
  std::vector<py::ssize_t> shape{py::ssize_t(held->size())};
  if (Columns) shape.push_back(Columns);
  return py::array_t<S>(shape, reinterpret_cast<const S*>(held->data()), owner);
}

py::object attribute_value(const AttrValue& v) {
  return std::visit([](const auto& x) -> py::object { return py::cast(x); }, v);
}

}  // namespace

py::dict read_scene_file(const std::string& path) {
  Scene scene;
  BodyRows rows;
  {
    py::gil_scoped_release release;
    scene = read_scene(path);
  }
  py::dict d;
  py::dict attributes;
  for (const auto& [key, value] : scene.attributes) attributes[py::str(key)] = attribute_value(value);
  d["attributes"] = attributes;
  d["radius_low"] = scene.radius_low ? py::cast(*scene.radius_low) : py::none();
  d["radius_high"] = scene.radius_high ? py::cast(*scene.radius_high) : py::none();
  d["spheres"] = scene.sphere_count();
  d["ellipsoids"] = scene.ellipsoid_count();
  const bool shapes = scene.ellipsoid_count() > 0;
  {
    py::gil_scoped_release release;
    rows = body_rows(std::move(scene), shapes);
  }
  d["positions"] = owned_rows<Vec3<double>, 3>(std::move(rows.position));
  d["radii"] = owned_rows<double, 0>(std::move(rows.radius));
  d["semi_axes"] = shapes ? py::object(owned_rows<Vec3<double>, 3>(std::move(rows.semi_axes))) : py::none();
  d["orientations"] =
      shapes ? py::object(owned_rows<Quat<double>, 4>(std::move(rows.orientation))) : py::none();
  return d;
}

void write_scene_file(const std::string& path, const py::object& positions, const py::object& radii,
                      const py::object& semi_axes, const py::object& orientations, const py::dict& attributes,
                      std::optional<double> radius_low, std::optional<double> radius_high) {
  const HostBodies bodies(positions, radii, semi_axes, orientations);
  const BodiesView v = bodies.view();
  Scene scene;
  scene.radius_low = radius_low;
  scene.radius_high = radius_high;
  for (const auto& [key, value] : attributes) {
    const std::string name = py::str(key);
    if (py::isinstance<py::bool_>(value) || py::isinstance<py::int_>(value))
      scene.attributes[name] = value.cast<std::int64_t>();
    else if (py::isinstance<py::float_>(value))
      scene.attributes[name] = value.cast<double>();
    else if (py::isinstance<py::str>(value))
      scene.attributes[name] = value.cast<std::string>();
    else
      throw py::value_error("attributes['" + name + "']: an int, a float or a str");
  }
  std::size_t spheres = v.size();
  if (!v.shape.empty()) {
    spheres = 0;
    while (spheres < v.size() && v.shape[spheres] == Shape::sphere) ++spheres;
    for (std::size_t i = spheres; i < v.size(); ++i)
      if (v.shape[i] == Shape::sphere)
        throw py::value_error("write_scene: body " + std::to_string(i) +
                              " is a sphere (equal semi-axes) after "
                              "ellipsoid " +
                              std::to_string(spheres) +
                              ": a scene file numbers its spheres first (docs/FORMAT.md §1)");
  }
  py::gil_scoped_release release;
  scene.sphere_position.assign(v.position.begin(), v.position.begin() + spheres);
  scene.sphere_radius.assign(v.radius.begin(), v.radius.begin() + spheres);
  for (std::size_t i = spheres; i < v.size(); ++i) {
    scene.ellipsoid_position.push_back(v.position[i]);
    scene.ellipsoid_semi_axes.push_back(v.semi_axes[i]);
    const Quat<double> q = v.orientation[i];
    scene.ellipsoid_orientation.push_back({q.w, q.x, q.y, q.z});
  }
  write_scene(path, scene);
}

PyContacts read_contacts_file(const std::string& path) {
  ContactFile file;
  {
    py::gil_scoped_release release;
    file = read_contacts(path);
  }
  RunRecord r;
  if (file.precision == "fp32") r.precision = Precision::fp32;
  if (file.precision == "mixed") r.precision = Precision::mixed;
  r.attributes = std::move(file.attributes);
  if (auto it = r.attributes.find("backend"); it != r.attributes.end())
    if (const auto* s = std::get_if<std::string>(&it->second))
      r.backend = *s == "cuda" ? Backend::cuda : Backend::cpu;
  if (auto it = r.attributes.find("bodies"); it != r.attributes.end())
    if (const auto* n = std::get_if<std::int64_t>(&it->second)) r.bodies = std::uint64_t(*n);
  if (auto it = r.attributes.find("precision_choice"); it != r.attributes.end())
    if (const auto* s = std::get_if<std::string>(&it->second)) r.precision_reason = *s;
  return PyContacts(std::move(file.contacts), std::move(r));
}

}  // namespace cg::python
