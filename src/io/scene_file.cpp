// scene_file.cpp: scene files (docs/FORMAT.md §1) through the HDF5 C API (see scene_file.hpp).
#include "io/scene_file.hpp"

#include <fmt/format.h>
#include <hdf5.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "io/attributes.hpp"
#include "io/datasets.hpp"
#include "io/hdf5_handle.hpp"

namespace cg {

using namespace h5;  // NOLINT: the io layer's own helpers

static_assert(sizeof(Vec3<double>) == 3 * sizeof(double) && std::is_standard_layout_v<Vec3<double>>);
static_assert(sizeof(std::array<double, 4>) == 4 * sizeof(double));

namespace {

constexpr hsize_t kReadChunkRows = hsize_t(1) << 20;  // rows validated per read
// (the orientation check is the engine's: cg::kQuaternionTolerance, core/shape.hpp)

// ---- scene reading ---------------------------------------------------------------------------

// An opened scene file: datasets with checked types and shapes, root attributes read.
struct SceneSource {
  Where where;
  Handle file;
  bool has_spheres = false, has_ellipsoids = false;
  Dataset sphere_position, sphere_radius;
  Dataset ellipsoid_position, ellipsoid_semi_axes, ellipsoid_orientation;
  // docs/FORMAT.md §5 (absent: nullopt)
  std::optional<Dataset> sphere_velocity, sphere_angular_velocity, ellipsoid_velocity,
      ellipsoid_angular_velocity;
  std::size_t spheres = 0, ellipsoids = 0;
  std::optional<double> radius_low, radius_high;
  bool xyzw = false;  // root attribute quaternion_order = "xyzw": orientations stored scalar last
  Attributes attributes;

  explicit SceneSource(const std::string& path) : where(path, false) {}
};

// The members of a group for messages: "position (2000, 3), radius (2000), params (group)" (at most
// a dozen; "" for an empty group).
herr_t collect_link_name(hid_t, const char* name, const H5L_info_t*, void* names) {
  static_cast<std::vector<std::string>*>(names)->push_back(name);
  return 0;
}

std::string group_listing(const Where& where, hid_t file, const std::string& group) {
  std::vector<std::string> names;
  {
    Handle g = checked(H5Gopen2(file, group.c_str(), H5P_DEFAULT), H5Gclose, where,
                       fmt::format("{}: cannot open the group", group));
    if (H5Literate(g, H5_INDEX_NAME, H5_ITER_INC, nullptr, collect_link_name, &names) < 0)
      where.fail(fmt::format("{}: cannot list the group", group));
  }
  std::string out;
  const std::size_t shown = std::min<std::size_t>(names.size(), 12);
  for (std::size_t k = 0; k < shown; ++k) {
    const std::string path = (group == "/" ? "/" : group + "/") + names[k];
    std::string what = "(not readable)";
    if (path_exists(where, file, path)) {
      const H5I_type_t type = object_type(where, file, path);
      if (type == H5I_GROUP) {
        what = "(group)";
      } else if (type == H5I_DATASET) {
        Handle d = checked(H5Dopen2(file, path.c_str(), H5P_DEFAULT), H5Dclose, where,
                           fmt::format("{}: cannot open the dataset", path));
        Handle space =
            checked(H5Dget_space(d), H5Sclose, where, fmt::format("{}: cannot read the shape", path));
        const int rank = H5Sget_simple_extent_ndims(space);
        std::vector<hsize_t> dims(static_cast<std::size_t>(std::max(rank, 0)));
        if (rank > 0) H5Sget_simple_extent_dims(space, dims.data(), nullptr);
        what = rank >= 0 ? shape_text(dims) : "(dataset)";
      }
    }
    out += fmt::format("{}{} {}", k ? ", " : "", path, what);
  }
  if (names.size() > shown) out += fmt::format(" and {} more", names.size() - shown);
  return out;
}

// A dataset the scene needs inside `group`: missing, the message names what the group holds.
Dataset scene_dataset(const Where& where, hid_t file, const std::string& group, const char* name,
                      hsize_t cols) {
  const std::string path = group + "/" + name;
  if (!path_exists(where, file, path)) {
    const std::string held = group_listing(where, file, group);
    where.bad(fmt::format("{}: missing dataset ({} holds {})", path, group,
                          held.empty() ? std::string("nothing") : held));
  }
  return open_dataset(where, file, path, cols, Element::real);
}

// radius_low / radius_high (docs/FORMAT.md §1): a finite number >= 0 when present.
std::optional<double> radius_bound(const Where& where, hid_t file, const RawAttributes& raw,
                                   const char* name) {
  const std::optional<double> value = number_attribute(where, file, raw, name);
  if (value && !(std::isfinite(*value) && *value >= 0))
    where.bad(fmt::format("root attribute {} = {} is not a finite number >= 0", name, *value));
  return value;
}

// A motion dataset (docs/FORMAT.md §5) when present: (N, 3) reals with the rows of its group.
std::optional<Dataset> open_motion(const Where& w, hid_t file, const char* name, const Dataset& rows_of) {
  if (!path_exists(w, file, name)) return std::nullopt;
  Dataset d = open_dataset(w, file, name, 3, Element::real);
  require_rows(w, d, rows_of);
  return d;
}

void open_scene(SceneSource& s) {
  const Where& w = s.where;
  s.file = open_file_for_reading(w);
  const RawAttributes raw = root_attributes(w, s.file);
  s.radius_low = radius_bound(w, s.file, raw, "radius_low");
  s.radius_high = radius_bound(w, s.file, raw, "radius_high");
  if (s.radius_low && s.radius_high && *s.radius_low > *s.radius_high) {
    w.bad(fmt::format("root attributes radius_low = {} > radius_high = {}", *s.radius_low, *s.radius_high));
  }

  if (const std::optional<std::string> order = string_attribute(w, s.file, raw, "quaternion_order")) {
    if (*order != "wxyz" && *order != "xyzw")
      w.bad(
          fmt::format("root attribute quaternion_order = \"{}\": expected \"wxyz\" (the default) or \"xyzw\" "
                      "(SciPy's Rotation.as_quat order)",
                      *order));
    s.xyzw = *order == "xyzw";
  }

  s.has_spheres = group_exists(w, s.file, "/spheres");
  if (s.has_spheres) {
    s.sphere_position = scene_dataset(w, s.file, "/spheres", "position", 3);
    s.sphere_radius = scene_dataset(w, s.file, "/spheres", "radius", 0);
    require_rows(w, s.sphere_radius, s.sphere_position);
    s.spheres = s.sphere_position.rows;
    s.sphere_velocity = open_motion(w, s.file, "/spheres/velocity", s.sphere_position);
    s.sphere_angular_velocity = open_motion(w, s.file, "/spheres/angular_velocity", s.sphere_position);
  }
  s.has_ellipsoids = group_exists(w, s.file, "/ellipsoids");
  if (s.has_ellipsoids) {
    s.ellipsoid_position = scene_dataset(w, s.file, "/ellipsoids", "position", 3);
    s.ellipsoid_semi_axes = scene_dataset(w, s.file, "/ellipsoids", "semi_axes", 3);
    s.ellipsoid_orientation = scene_dataset(w, s.file, "/ellipsoids", "orientation", 4);
    require_rows(w, s.ellipsoid_semi_axes, s.ellipsoid_position);
    require_rows(w, s.ellipsoid_orientation, s.ellipsoid_position);
    s.ellipsoids = s.ellipsoid_position.rows;
    s.ellipsoid_velocity = open_motion(w, s.file, "/ellipsoids/velocity", s.ellipsoid_position);
    s.ellipsoid_angular_velocity =
        open_motion(w, s.file, "/ellipsoids/angular_velocity", s.ellipsoid_position);
  }
  if (s.spheres + s.ellipsoids == 0) {
    if (s.has_spheres || s.has_ellipsoids) w.bad("scene has no bodies (its datasets have 0 rows)");
    const std::string held = group_listing(w, s.file, "/");
    w.bad(fmt::format(
        "scene has no bodies: no /spheres or /ellipsoids group; the file holds {}. A scene keeps spheres in "
        "/spheres/position (N, 3) and /spheres/radius (N), ellipsoids in /ellipsoids/position, "
        "/ellipsoids/semi_axes and /ellipsoids/orientation",
        held.empty() ? std::string("nothing") : held));
  }
  // (the generator's parameters mean nothing here: only what raw_attributes decoded)
  s.attributes = other_attributes(raw, {"radius_low", "radius_high", "quaternion_order"});
}

// Row checks; `row` is the row number in the file.
void check_finite(const SceneSource& s, const Dataset& d, hsize_t row, const double* values, int n) {
  for (int k = 0; k < n; ++k) {
    if (!std::isfinite(values[k]))
      s.where.bad(fmt::format("{} row {}: value {} is not finite", d.name, row, values[k]));
  }
}

void check_bounds(const SceneSource& s, const Dataset& d, hsize_t row, double r, const char* what) {
  if ((s.radius_low && r < *s.radius_low) || (s.radius_high && r > *s.radius_high)) {
    s.where.bad(fmt::format("{} row {}: {} {} is outside [radius_low, radius_high] = [{}, {}]", d.name, row,
                            what, r, s.radius_low ? fmt::format("{}", *s.radius_low) : std::string("-inf"),
                            s.radius_high ? fmt::format("{}", *s.radius_high) : std::string("inf")));
  }
}

// Rows [first, first + count) of a motion dataset, when present, into `out` (checked finite).
void read_motion(const SceneSource& s, const std::optional<Dataset>& d, hsize_t first, hsize_t count,
                 std::vector<Vec3<double>>& out) {
  if (!d) return;
  out.resize(count);
  if (count > 0) read_rows_f64(s.where, *d, first, count, &out[0].x);
  hsize_t from = count;  // the first row that is not finite, found in parallel; its message sequential
  const int threads = count < 65536 ? 1 : omp_get_max_threads();
#pragma omp parallel for num_threads(threads) reduction(min : from) schedule(static) if (threads > 1)
  for (hsize_t i = 0; i < count; ++i) {
    if (!(std::isfinite(out[i].x) && std::isfinite(out[i].y) && std::isfinite(out[i].z)) && i < from)
      from = i;
  }
  for (hsize_t i = from; i < count; ++i) check_finite(s, *d, first + i, &out[i].x, 3);
}

// Reads and validates sphere rows [first, first + count) into out (appended), chunk by chunk, into
// HostVector storage (no zero sweep; huge pages for the first touch by the reader).

void read_spheres(const SceneSource& s, hsize_t first, hsize_t count, Scene& out) {
  out.sphere_position.resize(count);
  out.sphere_radius.resize(count);
  // kReadChunkRows per thread: a chunk of 2^20 rows is only 6 + 2 blocks of 4 MiB for read_rows_f64,
  // so chunks of that size would leave most of a large team idle (BENCHMARKS.md §4).
  const hsize_t chunk_rows = kReadChunkRows * static_cast<hsize_t>(std::max(1, omp_get_max_threads()));
  for (hsize_t done = 0; done < count; done += chunk_rows) {
    hsize_t n = std::min(chunk_rows, count - done);
    Vec3<double>* position = out.sphere_position.data() + done;
    double* radius = out.sphere_radius.data() + done;
    read_rows_f64(s.where, s.sphere_position, first + done, n, &position->x);
    read_rows_f64(s.where, s.sphere_radius, first + done, n, radius);
    // Validation in parallel: the first bad row of the chunk (smallest index, whatever the threads),
    // then the sequential checks from there, which name it exactly as before.
    hsize_t from = n;
    {
      const double lo = s.radius_low ? *s.radius_low : -std::numeric_limits<double>::infinity();
      const double hi = s.radius_high ? *s.radius_high : std::numeric_limits<double>::infinity();
      const int threads = n < 65536 ? 1 : omp_get_max_threads();
#pragma omp parallel for num_threads(threads) reduction(min : from) schedule(static) if (threads > 1)
      for (hsize_t i = 0; i < n; ++i) {
        const Vec3<double> p = position[i];
        const double r = radius[i];
        if (!(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z) && std::isfinite(r) && r > 0 &&
              !(r < lo) && !(r > hi)) &&
            i < from) {
          from = i;
        }
      }
    }
    for (hsize_t i = from; i < n; ++i) {
      hsize_t row = first + done + i;
      check_finite(s, s.sphere_position, row, &position[i].x, 3);
      check_finite(s, s.sphere_radius, row, &radius[i], 1);
      if (!(radius[i] > 0))
        s.where.bad(fmt::format("{} row {}: radius {} is not > 0", s.sphere_radius.name, row, radius[i]));
      check_bounds(s, s.sphere_radius, row, radius[i], "radius");
    }
  }
}

void read_ellipsoids(const SceneSource& s, hsize_t first, hsize_t count, Scene& out) {
  out.ellipsoid_position.resize(count);
  out.ellipsoid_semi_axes.resize(count);
  out.ellipsoid_orientation.resize(count);
  // As read_spheres: chunks of kReadChunkRows per thread read in parallel, then validated in parallel
  // up to the first bad row, whose message the sequential checks write.
  const hsize_t chunk_rows = kReadChunkRows * static_cast<hsize_t>(std::max(1, omp_get_max_threads()));
  for (hsize_t done = 0; done < count; done += chunk_rows) {
    hsize_t n = std::min(chunk_rows, count - done);
    Vec3<double>* position = out.ellipsoid_position.data() + done;
    Vec3<double>* axes = out.ellipsoid_semi_axes.data() + done;
    std::array<double, 4>* orientation = out.ellipsoid_orientation.data() + done;
    read_rows_f64(s.where, s.ellipsoid_position, first + done, n, &position->x);
    read_rows_f64(s.where, s.ellipsoid_semi_axes, first + done, n, &axes->x);
    read_rows_f64(s.where, s.ellipsoid_orientation, first + done, n, orientation->data());
    hsize_t from = n;
    const int threads = n < 65536 ? 1 : omp_get_max_threads();
    {
      const double lo = s.radius_low ? *s.radius_low : -std::numeric_limits<double>::infinity();
      const double hi = s.radius_high ? *s.radius_high : std::numeric_limits<double>::infinity();
#pragma omp parallel for num_threads(threads) reduction(min : from) schedule(static) if (threads > 1)
      for (hsize_t i = 0; i < n; ++i) {
        const Vec3<double> p = position[i], a = axes[i];
        const std::array<double, 4>& q = orientation[i];
        const double bound = std::max({a.x, a.y, a.z});
        const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        const bool good = std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z) &&
                          std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z) && a.x > 0 &&
                          a.y > 0 && a.z > 0 && !(bound < lo) && !(bound > hi) && std::isfinite(q[0]) &&
                          std::isfinite(q[1]) && std::isfinite(q[2]) && std::isfinite(q[3]) &&
                          std::abs(norm - 1) <= kQuaternionTolerance;
        if (!good && i < from) from = i;
      }
    }
    for (hsize_t i = from; i < n; ++i) {
      hsize_t row = first + done + i;
      check_finite(s, s.ellipsoid_position, row, &position[i].x, 3);
      check_finite(s, s.ellipsoid_semi_axes, row, &axes[i].x, 3);
      for (double a : {axes[i].x, axes[i].y, axes[i].z}) {
        if (!(a > 0))
          s.where.bad(fmt::format("{} row {}: semi-axis {} is not > 0", s.ellipsoid_semi_axes.name, row, a));
      }
      check_bounds(s, s.ellipsoid_semi_axes, row, std::max({axes[i].x, axes[i].y, axes[i].z}),
                   "bounding radius");
      const std::array<double, 4>& q = orientation[i];
      check_finite(s, s.ellipsoid_orientation, row, q.data(), 4);
      double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
      if (!(std::abs(norm - 1) <= kQuaternionTolerance)) {
        s.where.bad(fmt::format("{} row {}: quaternion ({}, {}, {}, {}) has norm {}, not 1 (tolerance {})",
                                s.ellipsoid_orientation.name, row, q[0], q[1], q[2], q[3], norm,
                                kQuaternionTolerance));
      }
    }
    if (s.xyzw) {  // to docs/FORMAT.md §1's (w, x, y, z)
#pragma omp parallel for num_threads(threads) schedule(static) if (threads > 1)
      for (hsize_t i = 0; i < n; ++i) {
        const std::array<double, 4> q = orientation[i];
        orientation[i] = {q[3], q[0], q[1], q[2]};
      }
    }
  }
}

Scene read_scene_range(const std::string& path, std::size_t first, std::size_t count, bool whole) {
  SceneSource s(path);
  open_scene(s);
  std::size_t total = s.spheres + s.ellipsoids;
  if (whole) {
    first = 0;
    count = total;
  } else if (first > total || count > total - first) {
    throw UsageError(fmt::format("{}: rows [{}, {}) requested, but the scene has {} bodies", path, first,
                                 first + count, total));
  }
  Scene scene;
  scene.source = path;
  scene.radius_low = s.radius_low;
  scene.radius_high = s.radius_high;
  scene.attributes = s.attributes;
  std::size_t end = first + count;
  if (first < s.spheres) {
    const std::size_t rows = std::min(end, s.spheres) - first;
    read_spheres(s, first, rows, scene);
    read_motion(s, s.sphere_velocity, first, rows, scene.sphere_velocity);
    read_motion(s, s.sphere_angular_velocity, first, rows, scene.sphere_angular_velocity);
  }
  if (end > s.spheres) {
    std::size_t e_first = std::max(first, s.spheres) - s.spheres;
    read_ellipsoids(s, e_first, end - s.spheres - e_first, scene);
    read_motion(s, s.ellipsoid_velocity, e_first, end - s.spheres - e_first, scene.ellipsoid_velocity);
    read_motion(s, s.ellipsoid_angular_velocity, e_first, end - s.spheres - e_first,
                scene.ellipsoid_angular_velocity);
  }
  return scene;
}

// ---- scene writing ---------------------------------------------------------------------------

}  // namespace

struct SceneFileWriter::Impl {
  TempOutput temp;  // declared first: destroyed after every handle below
  Where where;
  SceneFileHeader header;
  Handle file;
  Handle sphere_position, sphere_radius;
  Handle ellipsoid_position, ellipsoid_semi_axes, ellipsoid_orientation;
  Handle sphere_velocity, sphere_angular_velocity, ellipsoid_velocity, ellipsoid_angular_velocity;
  bool committed = false;

  Impl(const std::string& path, const SceneFileHeader& h) : temp(path), where(path, true), header(h) {}
};

SceneFileWriter::SceneFileWriter(const std::string& path, const SceneFileHeader& header) {
  LibraryLock lock;
  auto impl = std::make_unique<Impl>(path, header);
  Impl& m = *impl;
  m.file = create_file(m.where, m.temp.temp());
  const hsize_t n = header.spheres, e = header.ellipsoids;
  if (n > 0 || e == 0) {
    create_group(m.where, m.file, "/spheres");
    m.sphere_position = create_dataset(m.where, m.file, "/spheres/position", H5T_IEEE_F64LE, {n, 3});
    m.sphere_radius = create_dataset(m.where, m.file, "/spheres/radius", H5T_IEEE_F64LE, {n});
    if (header.sphere_motion) {
      m.sphere_velocity = create_dataset(m.where, m.file, "/spheres/velocity", H5T_IEEE_F64LE, {n, 3});
      m.sphere_angular_velocity =
          create_dataset(m.where, m.file, "/spheres/angular_velocity", H5T_IEEE_F64LE, {n, 3});
    }
  }
  if (e > 0) {
    create_group(m.where, m.file, "/ellipsoids");
    m.ellipsoid_position = create_dataset(m.where, m.file, "/ellipsoids/position", H5T_IEEE_F64LE, {e, 3});
    m.ellipsoid_semi_axes = create_dataset(m.where, m.file, "/ellipsoids/semi_axes", H5T_IEEE_F64LE, {e, 3});
    m.ellipsoid_orientation =
        create_dataset(m.where, m.file, "/ellipsoids/orientation", H5T_IEEE_F64LE, {e, 4});
    if (header.ellipsoid_motion) {
      m.ellipsoid_velocity = create_dataset(m.where, m.file, "/ellipsoids/velocity", H5T_IEEE_F64LE, {e, 3});
      m.ellipsoid_angular_velocity =
          create_dataset(m.where, m.file, "/ellipsoids/angular_velocity", H5T_IEEE_F64LE, {e, 3});
    }
  }
  Handle root = checked(H5Gopen2(m.file, "/", H5P_DEFAULT), H5Gclose, m.where, "cannot open the root group");
  if (header.radius_low) write_attribute(m.where, root, "radius_low", *header.radius_low);
  if (header.radius_high) write_attribute(m.where, root, "radius_high", *header.radius_high);
  for (const auto& [name, value] : header.attributes) {
    if (name == "radius_low" || name == "radius_high") continue;
    write_attribute(m.where, root, name, value);
  }
  m_impl = std::move(impl);
}

SceneFileWriter::~SceneFileWriter() {
  if (m_impl) {
    LibraryLock lock;
    m_impl.reset();  // handles closed, then the temporary removed (unless committed)
  }
}

namespace {
void check_block(const Where& where, const char* group, std::size_t first, std::size_t rows,
                 std::size_t total, std::initializer_list<std::size_t> sizes) {
  for (std::size_t size : sizes) {
    if (size != rows)
      throw Error(fmt::format("{}: {}: a block's arrays differ in length", where.file(), group));
  }
  if (first > total || rows > total - first) {
    throw Error(fmt::format("{}: {}: rows [{}, {}) outside the {} rows of the file", where.file(), group,
                            first, first + rows, total));
  }
}
}  // namespace

void SceneFileWriter::write_spheres(std::size_t first, std::span<const Vec3<double>> position,
                                    std::span<const double> radius) {
  LibraryLock lock;
  Impl& m = *m_impl;
  check_block(m.where, "/spheres", first, position.size(), m.header.spheres, {radius.size()});
  write_rows(m.where, m.sphere_position, "/spheres/position", first, position.size(), 3, H5T_NATIVE_DOUBLE,
             position.data());
  write_rows(m.where, m.sphere_radius, "/spheres/radius", first, radius.size(), 0, H5T_NATIVE_DOUBLE,
             radius.data());
}

void SceneFileWriter::write_ellipsoids(std::size_t first, std::span<const Vec3<double>> position,
                                       std::span<const Vec3<double>> semi_axes,
                                       std::span<const std::array<double, 4>> orientation) {
  LibraryLock lock;
  Impl& m = *m_impl;
  check_block(m.where, "/ellipsoids", first, position.size(), m.header.ellipsoids,
              {semi_axes.size(), orientation.size()});
  const hsize_t n = position.size();
  write_rows(m.where, m.ellipsoid_position, "/ellipsoids/position", first, n, 3, H5T_NATIVE_DOUBLE,
             position.data());
  write_rows(m.where, m.ellipsoid_semi_axes, "/ellipsoids/semi_axes", first, n, 3, H5T_NATIVE_DOUBLE,
             semi_axes.data());
  write_rows(m.where, m.ellipsoid_orientation, "/ellipsoids/orientation", first, n, 4, H5T_NATIVE_DOUBLE,
             orientation.data());
}

void SceneFileWriter::write_sphere_motion(std::size_t first, std::span<const Vec3<double>> velocity,
                                          std::span<const Vec3<double>> angular_velocity) {
  LibraryLock lock;
  Impl& m = *m_impl;
  if (!m.header.sphere_motion) throw Error(fmt::format("{}: /spheres: no motion datasets", m.where.file()));
  check_block(m.where, "/spheres", first, velocity.size(), m.header.spheres, {angular_velocity.size()});
  write_rows(m.where, m.sphere_velocity, "/spheres/velocity", first, velocity.size(), 3, H5T_NATIVE_DOUBLE,
             velocity.data());
  write_rows(m.where, m.sphere_angular_velocity, "/spheres/angular_velocity", first, velocity.size(), 3,
             H5T_NATIVE_DOUBLE, angular_velocity.data());
}

void SceneFileWriter::write_ellipsoid_motion(std::size_t first, std::span<const Vec3<double>> velocity,
                                             std::span<const Vec3<double>> angular_velocity) {
  LibraryLock lock;
  Impl& m = *m_impl;
  if (!m.header.ellipsoid_motion)
    throw Error(fmt::format("{}: /ellipsoids: no motion datasets", m.where.file()));
  check_block(m.where, "/ellipsoids", first, velocity.size(), m.header.ellipsoids, {angular_velocity.size()});
  write_rows(m.where, m.ellipsoid_velocity, "/ellipsoids/velocity", first, velocity.size(), 3,
             H5T_NATIVE_DOUBLE, velocity.data());
  write_rows(m.where, m.ellipsoid_angular_velocity, "/ellipsoids/angular_velocity", first, velocity.size(), 3,
             H5T_NATIVE_DOUBLE, angular_velocity.data());
}

void SceneFileWriter::commit() {
  LibraryLock lock;
  Impl& m = *m_impl;
  if (m.committed) throw Error(fmt::format("{}: scene file committed twice", m.where.file()));
  m.sphere_position.close(m.where, "cannot close /spheres/position");
  m.sphere_radius.close(m.where, "cannot close /spheres/radius");
  m.ellipsoid_position.close(m.where, "cannot close /ellipsoids/position");
  m.ellipsoid_semi_axes.close(m.where, "cannot close /ellipsoids/semi_axes");
  m.ellipsoid_orientation.close(m.where, "cannot close /ellipsoids/orientation");
  m.sphere_velocity.close(m.where, "cannot close /spheres/velocity");
  m.sphere_angular_velocity.close(m.where, "cannot close /spheres/angular_velocity");
  m.ellipsoid_velocity.close(m.where, "cannot close /ellipsoids/velocity");
  m.ellipsoid_angular_velocity.close(m.where, "cannot close /ellipsoids/angular_velocity");
  m.file.close(m.where, "cannot close (flush) the file");
  m.temp.commit();
  m.committed = true;
}

// ---- public API --------------------------------------------------------------------------------

Scene read_scene(const std::string& path) {
  LibraryLock lock;
  return read_scene_range(path, 0, 0, true);
}

Scene read_scene_rows(const std::string& path, std::size_t first, std::size_t count) {
  LibraryLock lock;
  return read_scene_range(path, first, count, false);
}

BodyRows body_rows(Scene&& scene, bool shapes) {
  const std::size_t n = scene.sphere_count(), e = scene.ellipsoid_count();
  if (e > 0 && !shapes) throw Error("body_rows: a scene with ellipsoids needs shape rows");
  BodyRows rows;
  if (!shapes) {
    rows.position = std::move(scene.sphere_position);
    rows.radius = std::move(scene.sphere_radius);
    return rows;
  }
  // A scene of ellipsoids alone keeps its centres and semi-axes as read (their rows are the bodies'
  // rows): no copy, and no first touch of another gigabyte at 2^24 bodies.
  const bool alone = n == 0;
  if (alone) {
    rows.position = std::move(scene.ellipsoid_position);
    rows.semi_axes = std::move(scene.ellipsoid_semi_axes);
  } else {
    rows.position.resize(n + e);
    rows.semi_axes.resize(n + e);
  }
  rows.radius.resize(n + e);
  rows.shape.resize(n + e);
  rows.orientation.resize(n + e);
  const Quat<double> identity{1, 0, 0, 0};
  // Parallel copies: the first touch of the rows, on the threads that later read them.
  const int threads = n + e < 65536 ? 1 : omp_get_max_threads();
#pragma omp parallel for num_threads(threads) schedule(static) if (threads > 1)
  for (std::size_t i = 0; i < n; ++i) {
    const double r = scene.sphere_radius[i];
    rows.position[i] = scene.sphere_position[i];
    rows.radius[i] = r;
    rows.shape[i] = Shape::sphere;
    rows.semi_axes[i] = {r, r, r};
    rows.orientation[i] = identity;
  }
#pragma omp parallel for num_threads(threads) schedule(static) if (threads > 1)
  for (std::size_t j = 0; j < e; ++j) {
    const Vec3<double> a = alone ? rows.semi_axes[j] : scene.ellipsoid_semi_axes[j];
    const std::array<double, 4>& q = scene.ellipsoid_orientation[j];
    if (!alone) {
      rows.position[n + j] = scene.ellipsoid_position[j];
      rows.semi_axes[n + j] = a;
    }
    rows.radius[n + j] = std::max({a.x, a.y, a.z});
    rows.shape[n + j] = Shape::ellipsoid;
    rows.orientation[n + j] = {q[0], q[1], q[2], q[3]};
  }
  scene.sphere_position = {};
  scene.sphere_radius = {};
  scene.ellipsoid_position = {};
  scene.ellipsoid_semi_axes = {};
  scene.ellipsoid_orientation = {};
  return rows;
}

SceneShape read_scene_shape(const std::string& path) {
  LibraryLock lock;
  SceneSource s(path);
  open_scene(s);
  return SceneShape{s.spheres, s.ellipsoids};
}

void write_scene(const std::string& path, const Scene& scene) {
  const std::size_t n = scene.sphere_count(), e = scene.ellipsoid_count();
  const bool sphere_motion = !scene.sphere_velocity.empty() || !scene.sphere_angular_velocity.empty();
  const bool ellipsoid_motion =
      !scene.ellipsoid_velocity.empty() || !scene.ellipsoid_angular_velocity.empty();
  if (scene.sphere_position.size() != n || scene.ellipsoid_position.size() != e ||
      scene.ellipsoid_orientation.size() != e ||
      (sphere_motion && (scene.sphere_velocity.size() != n || scene.sphere_angular_velocity.size() != n)) ||
      (ellipsoid_motion &&
       (scene.ellipsoid_velocity.size() != e || scene.ellipsoid_angular_velocity.size() != e))) {
    throw Error(fmt::format("{}: write_scene: the scene's arrays differ in length", path));
  }
  SceneFileHeader header;
  header.spheres = n;
  header.ellipsoids = e;
  header.sphere_motion = sphere_motion && (n > 0 || e == 0);
  header.ellipsoid_motion = ellipsoid_motion && e > 0;
  header.radius_low = scene.radius_low;
  header.radius_high = scene.radius_high;
  header.attributes = scene.attributes;
  SceneFileWriter writer(path, header);
  writer.write_spheres(0, scene.sphere_position, scene.sphere_radius);
  writer.write_ellipsoids(0, scene.ellipsoid_position, scene.ellipsoid_semi_axes,
                          scene.ellipsoid_orientation);
  if (header.sphere_motion)
    writer.write_sphere_motion(0, scene.sphere_velocity, scene.sphere_angular_velocity);
  if (header.ellipsoid_motion)
    writer.write_ellipsoid_motion(0, scene.ellipsoid_velocity, scene.ellipsoid_angular_velocity);
  writer.commit();
}

}  // namespace cg
