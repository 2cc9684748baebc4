// hdf5_io.cpp: scene files (CONTRACT §1) and contact files (§2) through the HDF5 C API.
//
// Invariants:
// - every HDF5 identifier is owned by exactly one Handle and closed exactly once;
// - HDF5's automatic error printing is off; every failing HDF5 call becomes one exception whose
//   message starts with the file name: InputError while reading (bad or unreadable input), IoError
//   while writing; data checks name the file, the dataset and the first bad row (file row numbers);
// - the library is entered by one thread at a time (a process-wide mutex: Debian's serial HDF5 is
//   not thread-safe);
// - writers write "<path>.tmp.<pid>" and rename it over path only after a successful close; on any
//   failure the temporary is removed;
// - written objects carry no timestamps (obj_track_times off) and attributes are written in a fixed
//   order, so equal content gives byte-identical files.
#include "hdf5_io.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <hdf5.h>
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <mutex>
#include <optional>
#include <type_traits>
#include <utility>

#include "host/huge_pages.hpp"

namespace cg {

static_assert(sizeof(Vec3<double>) == 3 * sizeof(double) && std::is_standard_layout_v<Vec3<double>>);
static_assert(sizeof(Vec3<float>) == 3 * sizeof(float) && std::is_standard_layout_v<Vec3<float>>);
static_assert(sizeof(std::array<double, 4>) == 4 * sizeof(double));

namespace {

constexpr hsize_t kReadChunkRows = hsize_t(1) << 20;  // rows validated per read
constexpr double kQuaternionTolerance = 1e-6;
constexpr const char* kSoftwareVersion = CONTACTGRID_VERSION;

// ---- library access --------------------------------------------------------------------------

std::mutex g_hdf5_mutex;

// Held by every public entry point: serializes the library and silences its error printing.
class LibraryLock {
 public:
  LibraryLock() : m_lock(g_hdf5_mutex) {
    static const bool quiet = [] {
      H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
      return true;
    }();
    (void)quiet;
  }

 private:
  std::lock_guard<std::mutex> m_lock;
};

herr_t take_innermost_error(unsigned n, const H5E_error2_t* error, void* data) {
  if (n == 0 && error != nullptr && error->desc != nullptr) *static_cast<std::string*>(data) = error->desc;
  return 0;
}

// The most specific message on HDF5's error stack (then cleared); "" when there is none.
std::string hdf5_detail() {
  std::string detail;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, take_innermost_error, &detail);
  H5Eclear2(H5E_DEFAULT);
  return detail;
}

// The file an operation is about, and which exception its failures raise.
class Where {
 public:
  Where(std::string file, bool writing) : m_file(std::move(file)), m_writing(writing) {}
  const std::string& file() const { return m_file; }

  // An HDF5 call failed: the library's own reason is appended.
  [[noreturn]] void fail(const std::string& what) const {
    std::string detail = hdf5_detail();
    std::string message = fmt::format("{}: {}", m_file, what);
    if (!detail.empty()) message += fmt::format(" (HDF5: {})", detail);
    if (m_writing) throw IoError(message);
    throw InputError(message);
  }
  // The data is wrong (no HDF5 failure involved).
  [[noreturn]] void bad(const std::string& what) const {
    throw InputError(fmt::format("{}: {}", m_file, what));
  }

 private:
  std::string m_file;
  bool m_writing;
};

// Owner of one HDF5 identifier.
class Handle {
 public:
  using Closer = herr_t (*)(hid_t);
  Handle() = default;
  Handle(hid_t id, Closer closer) noexcept : m_id(id), m_closer(closer) {}
  ~Handle() { reset(); }
  Handle(Handle&& other) noexcept
      : m_id(std::exchange(other.m_id, H5I_INVALID_HID)), m_closer(other.m_closer) {}
  Handle& operator=(Handle&& other) noexcept {
    if (this != &other) {
      reset();
      m_id = std::exchange(other.m_id, H5I_INVALID_HID);
      m_closer = other.m_closer;
    }
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;

  hid_t get() const noexcept { return m_id; }
  operator hid_t() const noexcept { return m_id; }  // NOLINT: hand to the C API directly

  // Close now and check (a file's close flushes: its failure is a write failure).
  void close(const Where& where, const std::string& what) {
    hid_t id = std::exchange(m_id, H5I_INVALID_HID);
    if (id >= 0 && m_closer(id) < 0) where.fail(what);
  }
  void reset() noexcept {
    if (m_id >= 0) m_closer(m_id);
    m_id = H5I_INVALID_HID;
  }

 private:
  hid_t m_id = H5I_INVALID_HID;
  Closer m_closer = nullptr;
};

Handle checked(hid_t id, Handle::Closer closer, const Where& where, const std::string& what) {
  if (id < 0) where.fail(what);
  return Handle(id, closer);
}
void check(herr_t status, const Where& where, const std::string& what) {
  if (status < 0) where.fail(what);
}

Handle make_space(const Where& where, const std::vector<hsize_t>& dims) {
  return checked(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr), H5Sclose, where,
                 "cannot create a dataspace");
}
Handle scalar_space(const Where& where) {
  return checked(H5Screate(H5S_SCALAR), H5Sclose, where, "cannot create a dataspace");
}
Handle string_type(const Where& where) {
  Handle type = checked(H5Tcopy(H5T_C_S1), H5Tclose, where, "cannot create a string type");
  check(H5Tset_size(type, H5T_VARIABLE), where, "cannot create a string type");
  check(H5Tset_cset(type, H5T_CSET_UTF8), where, "cannot create a string type");
  return type;
}

std::string shape_text(const std::vector<hsize_t>& dims) {
  std::string s = "(";
  for (std::size_t k = 0; k < dims.size(); ++k) s += fmt::format("{}{}", k ? ", " : "", dims[k]);
  return s + ")";
}

std::string type_text(hid_t type) {
  std::size_t bits = H5Tget_size(type) * 8;
  switch (H5Tget_class(type)) {
    case H5T_INTEGER:
      return fmt::format("{}-bit integer", bits);
    case H5T_FLOAT:
      return fmt::format("{}-bit float", bits);
    case H5T_STRING:
      return "string";
    case H5T_COMPOUND:
      return "compound";
    case H5T_ENUM:
      return "enum";
    case H5T_ARRAY:
      return "array";
    case H5T_VLEN:
      return "variable-length sequence";
    default:
      return "unsupported type";
  }
}

// ---- objects ---------------------------------------------------------------------------------

// True when every component of the absolute path exists as a link.
bool path_exists(const Where& where, hid_t file, const std::string& path) {
  std::size_t pos = 0;
  while (pos != std::string::npos) {
    pos = path.find('/', pos + 1);
    std::string prefix = path.substr(0, pos);
    htri_t exists = H5Lexists(file, prefix.c_str(), H5P_DEFAULT);
    if (exists < 0) where.fail(fmt::format("{}: cannot look up {}", path, prefix));
    if (exists == 0) return false;
  }
  return true;
}

H5I_type_t object_type(const Where& where, hid_t file, const std::string& path) {
  Handle object = checked(H5Oopen(file, path.c_str(), H5P_DEFAULT), H5Oclose, where,
                          fmt::format("{}: cannot open", path));
  return H5Iget_type(object);
}

// Whether a group exists (and is a group).
bool group_exists(const Where& where, hid_t file, const std::string& path) {
  if (!path_exists(where, file, path)) return false;
  if (object_type(where, file, path) != H5I_GROUP) where.bad(fmt::format("{} is not a group", path));
  return true;
}

Handle open_file_for_reading(const Where& where) {
  std::error_code ec;
  const std::string& path = where.file();
  if (!std::filesystem::exists(path, ec)) where.bad("no such file");
  if (!std::filesystem::is_regular_file(path, ec)) where.bad("not a regular file");
  htri_t is_hdf5 = H5Fis_hdf5(path.c_str());
  if (is_hdf5 < 0) where.fail("cannot read the file");
  if (is_hdf5 == 0) where.bad("not an HDF5 file");
  return checked(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose, where,
                 "cannot open the HDF5 file (truncated or damaged?)");
}

// A dataset whose shape is (rows) or (rows, cols), element type checked.
struct Dataset {
  std::string name;
  Handle id;
  hsize_t rows = 0;
  hsize_t cols = 0;  // 0: rank 1
};

enum class Element { real, integer };

Dataset open_dataset(const Where& where, hid_t file, const std::string& name, hsize_t cols, Element element) {
  if (!path_exists(where, file, name)) where.bad(fmt::format("{}: missing dataset", name));
  if (object_type(where, file, name) != H5I_DATASET) where.bad(fmt::format("{} is not a dataset", name));
  Dataset d;
  d.name = name;
  d.cols = cols;
  d.id = checked(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose, where,
                 fmt::format("{}: cannot open the dataset", name));

  Handle type = checked(H5Dget_type(d.id), H5Tclose, where, fmt::format("{}: cannot read the type", name));
  H5T_class_t type_class = H5Tget_class(type);
  std::size_t size = H5Tget_size(type);
  if (element == Element::real && !(type_class == H5T_FLOAT && (size == 4 || size == 8)))
    where.bad(fmt::format("{}: element type is {}; expected float64 or float32", name, type_text(type)));
  if (element == Element::integer && type_class != H5T_INTEGER)
    where.bad(fmt::format("{}: element type is {}; expected int64", name, type_text(type)));

  Handle space = checked(H5Dget_space(d.id), H5Sclose, where, fmt::format("{}: cannot read the shape", name));
  int rank = H5Sget_simple_extent_ndims(space);
  if (rank < 0) where.fail(fmt::format("{}: cannot read the shape", name));
  std::vector<hsize_t> dims(static_cast<std::size_t>(rank));
  if (rank > 0 && H5Sget_simple_extent_dims(space, dims.data(), nullptr) < 0)
    where.fail(fmt::format("{}: cannot read the shape", name));
  bool ok = cols == 0 ? rank == 1 : (rank == 2 && dims[1] == cols);
  if (!ok) {
    where.bad(fmt::format("{}: shape {}, expected {}", name, shape_text(dims),
                          cols == 0 ? std::string("(N)") : fmt::format("(N, {})", cols)));
  }
  d.rows = dims[0];
  return d;
}

// Rows [first, first + count) of d into out (count·max(cols,1) values of mem_type).
void read_rows(const Where& where, const Dataset& d, hsize_t first, hsize_t count, hid_t mem_type,
               void* out) {
  if (count == 0) return;
  std::string what = fmt::format("{}: cannot read rows {} to {}", d.name, first, first + count - 1);
  Handle file_space = checked(H5Dget_space(d.id), H5Sclose, where, what);
  std::vector<hsize_t> start{first}, extent{count};
  if (d.cols != 0) {
    start.push_back(0);
    extent.push_back(d.cols);
  }
  check(H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start.data(), nullptr, extent.data(), nullptr), where,
        what);
  Handle mem_space = make_space(where, extent);
  check(H5Dread(d.id, mem_type, mem_space, file_space, H5P_DEFAULT, out), where, what);
}

// The same rows as read_rows into float64 memory, read straight from the file with pread on all
// threads when the dataset is stored as plain bytes of that type: contiguous layout (no chunks, no
// filters, no external file), IEEE float64 little-endian, allocated. HDF5's own read runs on one thread
// (3 times slower than the page cache at 2^26 rows on the GPU host); anything else goes through it.
void read_rows_f64(const Where& where, const Dataset& d, hsize_t first, hsize_t count, double* out) {
  if (count == 0) return;
  static_assert(std::endian::native == std::endian::little, "direct reads assume a little-endian host");
  bool direct = false;
  haddr_t base = HADDR_UNDEF;
  {
    Handle dcpl(H5Dget_create_plist(d.id), H5Pclose);
    Handle type(H5Dget_type(d.id), H5Tclose);
    direct = dcpl.get() >= 0 && type.get() >= 0 && H5Pget_layout(dcpl) == H5D_CONTIGUOUS &&
             H5Pget_external_count(dcpl) == 0 && H5Tequal(type, H5T_IEEE_F64LE) > 0;
    if (direct) base = H5Dget_offset(d.id);
    if (base == HADDR_UNDEF) direct = false;
  }
  if (!direct) {
    read_rows(where, d, first, count, H5T_NATIVE_DOUBLE, out);
    return;
  }
  const std::uint64_t row_bytes = 8 * std::max<hsize_t>(d.cols, 1);
  const std::uint64_t offset = std::uint64_t(base) + std::uint64_t(first) * row_bytes;
  const std::uint64_t bytes = std::uint64_t(count) * row_bytes;
  const int fd = ::open(where.file().c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) where.bad(fmt::format("{}: cannot open for reading: {}", d.name, std::strerror(errno)));
  constexpr std::uint64_t kBlock = std::uint64_t(4) << 20;
  const auto blocks = static_cast<std::int64_t>((bytes + kBlock - 1) / kBlock);
  std::atomic<int> error{0};
  const int threads = blocks > 1 ? omp_get_max_threads() : 1;
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1) if (threads > 1)
  for (std::int64_t b = 0; b < blocks; ++b) {
    const std::uint64_t at = std::uint64_t(b) * kBlock, len = std::min(kBlock, bytes - at);
    auto* dst = reinterpret_cast<unsigned char*>(out) + at;
    std::uint64_t done = 0;
    while (done < len && error.load(std::memory_order_relaxed) == 0) {
      const ssize_t r = ::pread(fd, dst + done, len - done, static_cast<off_t>(offset + at + done));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) {
        int expected = 0;
        error.compare_exchange_strong(expected, r < 0 ? errno : EIO);  // 0 bytes: the file is truncated
        break;
      }
      done += static_cast<std::uint64_t>(r);
    }
  }
  ::close(fd);
  if (const int e = error.load()) {
    where.bad(
        fmt::format("{}: cannot read rows {} to {}: {}", d.name, first, first + count - 1,
                    e == EIO ? "the file ends before the dataset does (truncated?)" : std::strerror(e)));
  }
}

// ---- attributes ------------------------------------------------------------------------------

herr_t collect_attribute_name(hid_t, const char* name, const H5A_info_t*, void* data) {
  static_cast<std::vector<std::string>*>(data)->emplace_back(name);
  return 0;
}

std::vector<std::string> attribute_names(const Where& where, hid_t object) {
  std::vector<std::string> names;
  hsize_t index = 0;
  check(H5Aiterate2(object, H5_INDEX_NAME, H5_ITER_INC, &index, collect_attribute_name, &names), where,
        "cannot list the root attributes");
  return names;
}

// A scalar (or one-element) integer, float or string attribute; nullopt for other kinds.
std::optional<AttrValue> read_attribute(const Where& where, hid_t object, const std::string& name) {
  std::string what = fmt::format("root attribute {}: cannot read", name);
  Handle attr = checked(H5Aopen(object, name.c_str(), H5P_DEFAULT), H5Aclose, where, what);
  Handle space = checked(H5Aget_space(attr), H5Sclose, where, what);
  if (H5Sget_simple_extent_npoints(space) != 1) return std::nullopt;
  Handle type = checked(H5Aget_type(attr), H5Tclose, where, what);
  switch (H5Tget_class(type)) {
    case H5T_INTEGER: {
      std::int64_t value = 0;
      check(H5Aread(attr, H5T_NATIVE_INT64, &value), where, what);
      return value;
    }
    case H5T_FLOAT: {
      double value = 0;
      check(H5Aread(attr, H5T_NATIVE_DOUBLE, &value), where, what);
      return value;
    }
    case H5T_STRING: {
      htri_t variable = H5Tis_variable_str(type);
      if (variable < 0) where.fail(what);
      if (variable > 0) {
        Handle mem_type = string_type(where);
        check(H5Tset_cset(mem_type, H5Tget_cset(type)), where, what);
        char* text = nullptr;
        check(H5Aread(attr, mem_type, &text), where, what);
        std::string value = text != nullptr ? text : "";
        H5free_memory(text);
        return value;
      }
      std::size_t size = H5Tget_size(type);
      Handle mem_type = checked(H5Tcopy(type), H5Tclose, where, what);
      std::string buffer(size, '\0');
      check(H5Aread(attr, mem_type, buffer.data()), where, what);
      buffer.resize(std::strlen(buffer.c_str()));
      if (H5Tget_strpad(type) == H5T_STR_SPACEPAD) {
        while (!buffer.empty() && buffer.back() == ' ') buffer.pop_back();
      }
      return buffer;
    }
    default:
      return std::nullopt;
  }
}

Attributes read_root_attributes(const Where& where, hid_t file) {
  Handle root = checked(H5Gopen2(file, "/", H5P_DEFAULT), H5Gclose, where, "cannot open the root group");
  Attributes attributes;
  for (const std::string& name : attribute_names(where, root)) {
    if (auto value = read_attribute(where, root, name)) attributes.emplace(name, std::move(*value));
  }
  return attributes;
}

void write_attribute(const Where& where, hid_t object, const std::string& name, const AttrValue& value) {
  std::string what = fmt::format("cannot write root attribute {}", name);
  Handle space = scalar_space(where);
  if (const auto* i = std::get_if<std::int64_t>(&value)) {
    Handle attr = checked(H5Acreate2(object, name.c_str(), H5T_STD_I64LE, space, H5P_DEFAULT, H5P_DEFAULT),
                          H5Aclose, where, what);
    check(H5Awrite(attr, H5T_NATIVE_INT64, i), where, what);
  } else if (const auto* d = std::get_if<double>(&value)) {
    Handle attr = checked(H5Acreate2(object, name.c_str(), H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT),
                          H5Aclose, where, what);
    check(H5Awrite(attr, H5T_NATIVE_DOUBLE, d), where, what);
  } else {
    Handle type = string_type(where);
    Handle attr = checked(H5Acreate2(object, name.c_str(), type, space, H5P_DEFAULT, H5P_DEFAULT), H5Aclose,
                          where, what);
    const char* text = std::get<std::string>(value).c_str();
    check(H5Awrite(attr, type, &text), where, what);
  }
}

// ---- writing ---------------------------------------------------------------------------------

// "<path>.tmp.<pid>": removed on destruction unless renamed over path by commit().
class TempOutput {
 public:
  explicit TempOutput(std::string path)
      : m_path(std::move(path)), m_temp(m_path + ".tmp." + std::to_string(::getpid())) {}
  ~TempOutput() {
    if (!m_done) {
      std::error_code ec;
      std::filesystem::remove(m_temp, ec);
    }
  }
  TempOutput(const TempOutput&) = delete;
  TempOutput& operator=(const TempOutput&) = delete;

  const std::string& temp() const { return m_temp; }
  void commit() {
    if (std::rename(m_temp.c_str(), m_path.c_str()) != 0) {
      int error = errno;
      throw IoError(fmt::format("{}: cannot rename {} over it: {}", m_path, m_temp, std::strerror(error)));
    }
    m_done = true;
  }

 private:
  std::string m_path, m_temp;
  bool m_done = false;
};

Handle creation_properties(const Where& where, hid_t plist_class) {
  Handle plist = checked(H5Pcreate(plist_class), H5Pclose, where, "cannot create a property list");
  check(H5Pset_obj_track_times(plist, 0), where, "cannot set object properties");
  return plist;
}

Handle create_file(const Where& where, const std::string& name) {
  Handle fcpl = creation_properties(where, H5P_FILE_CREATE);
  return checked(H5Fcreate(name.c_str(), H5F_ACC_TRUNC, fcpl, H5P_DEFAULT), H5Fclose, where,
                 fmt::format("cannot create {}", name));
}

Handle create_group(const Where& where, hid_t file, const std::string& name) {
  Handle gcpl = creation_properties(where, H5P_GROUP_CREATE);
  Handle lcpl = checked(H5Pcreate(H5P_LINK_CREATE), H5Pclose, where, "cannot create a property list");
  check(H5Pset_create_intermediate_group(lcpl, 1), where, "cannot set link properties");
  return checked(H5Gcreate2(file, name.c_str(), lcpl, gcpl, H5P_DEFAULT), H5Gclose, where,
                 fmt::format("{}: cannot create the group", name));
}

// A contiguous dataset of the given file type and shape (no fill writes: every row gets written).
Handle create_dataset(const Where& where, hid_t file, const std::string& name, hid_t file_type,
                      const std::vector<hsize_t>& dims) {
  Handle space = make_space(where, dims);
  Handle dcpl = creation_properties(where, H5P_DATASET_CREATE);
  check(H5Pset_fill_time(dcpl, H5D_FILL_TIME_NEVER), where, "cannot set dataset properties");
  Handle lcpl = checked(H5Pcreate(H5P_LINK_CREATE), H5Pclose, where, "cannot create a property list");
  check(H5Pset_create_intermediate_group(lcpl, 1), where, "cannot set link properties");
  return checked(H5Dcreate2(file, name.c_str(), file_type, space, lcpl, dcpl, H5P_DEFAULT), H5Dclose, where,
                 fmt::format("{}: cannot create the dataset", name));
}

// Writes rows [first, first + count) of a dataset of `cols` columns (0: rank 1).
void write_rows(const Where& where, hid_t dataset, const std::string& name, hsize_t first, hsize_t count,
                hsize_t cols, hid_t mem_type, const void* data) {
  if (count == 0) return;
  std::string what = fmt::format("{}: cannot write rows {} to {}", name, first, first + count - 1);
  Handle file_space = checked(H5Dget_space(dataset), H5Sclose, where, what);
  std::vector<hsize_t> start{first}, extent{count};
  if (cols != 0) {
    start.push_back(0);
    extent.push_back(cols);
  }
  check(H5Sselect_hyperslab(file_space, H5S_SELECT_SET, start.data(), nullptr, extent.data(), nullptr), where,
        what);
  Handle mem_space = make_space(where, extent);
  check(H5Dwrite(dataset, mem_type, mem_space, file_space, H5P_DEFAULT, data), where, what);
}

template <class T>
struct TypeOf;
template <>
struct TypeOf<float> {
  static hid_t memory() { return H5T_NATIVE_FLOAT; }
  static hid_t file() { return H5T_IEEE_F32LE; }
};
template <>
struct TypeOf<double> {
  static hid_t memory() { return H5T_NATIVE_DOUBLE; }
  static hid_t file() { return H5T_IEEE_F64LE; }
};
template <>
struct TypeOf<std::int64_t> {
  static hid_t memory() { return H5T_NATIVE_INT64; }
  static hid_t file() { return H5T_STD_I64LE; }
};

// A whole dataset from a vector of T (scalars) or Vec3<T>.
template <class T>
void write_whole(const Where& where, hid_t file, const std::string& name, const std::vector<T>& values) {
  Handle dataset = create_dataset(where, file, name, TypeOf<T>::file(), {values.size()});
  write_rows(where, dataset, name, 0, values.size(), 0, TypeOf<T>::memory(), values.data());
}
template <class T>
void write_whole(const Where& where, hid_t file, const std::string& name,
                 const std::vector<Vec3<T>>& values) {
  Handle dataset = create_dataset(where, file, name, TypeOf<T>::file(), {values.size(), 3});
  write_rows(where, dataset, name, 0, values.size(), 3, TypeOf<T>::memory(), values.data());
}

// ---- scene reading ---------------------------------------------------------------------------

// An opened scene file: datasets with checked types and shapes, root attributes read.
struct SceneSource {
  Where where;
  Handle file;
  bool has_spheres = false, has_ellipsoids = false;
  Dataset sphere_position, sphere_radius;
  Dataset ellipsoid_position, ellipsoid_semi_axes, ellipsoid_orientation;
  std::size_t spheres = 0, ellipsoids = 0;
  std::optional<double> radius_low, radius_high;
  Attributes attributes;

  explicit SceneSource(const std::string& path) : where(path, false) {}
};

void require_rows(const Where& where, const Dataset& d, const Dataset& reference) {
  if (d.rows != reference.rows)
    where.bad(fmt::format("{}: {} rows, but {} has {}", d.name, d.rows, reference.name, reference.rows));
}

std::optional<double> radius_bound(const Where& where, Attributes& attributes, const char* name) {
  auto it = attributes.find(name);
  if (it == attributes.end()) return std::nullopt;
  double value = 0;
  if (const auto* d = std::get_if<double>(&it->second))
    value = *d;
  else if (const auto* i = std::get_if<std::int64_t>(&it->second))
    value = static_cast<double>(*i);
  else
    where.bad(fmt::format("root attribute {} is a string; expected a number", name));
  if (!std::isfinite(value) || value < 0)
    where.bad(fmt::format("root attribute {} = {} is not a finite number >= 0", name, value));
  attributes.erase(it);
  return value;
}

void open_scene(SceneSource& s) {
  const Where& w = s.where;
  s.file = open_file_for_reading(w);
  s.attributes = read_root_attributes(w, s.file);
  s.radius_low = radius_bound(w, s.attributes, "radius_low");
  s.radius_high = radius_bound(w, s.attributes, "radius_high");
  if (s.radius_low && s.radius_high && *s.radius_low > *s.radius_high) {
    w.bad(fmt::format("root attributes radius_low = {} > radius_high = {}", *s.radius_low, *s.radius_high));
  }

  s.has_spheres = group_exists(w, s.file, "/spheres");
  if (s.has_spheres) {
    s.sphere_position = open_dataset(w, s.file, "/spheres/position", 3, Element::real);
    s.sphere_radius = open_dataset(w, s.file, "/spheres/radius", 0, Element::real);
    require_rows(w, s.sphere_radius, s.sphere_position);
    s.spheres = s.sphere_position.rows;
  }
  s.has_ellipsoids = group_exists(w, s.file, "/ellipsoids");
  if (s.has_ellipsoids) {
    s.ellipsoid_position = open_dataset(w, s.file, "/ellipsoids/position", 3, Element::real);
    s.ellipsoid_semi_axes = open_dataset(w, s.file, "/ellipsoids/semi_axes", 3, Element::real);
    s.ellipsoid_orientation = open_dataset(w, s.file, "/ellipsoids/orientation", 4, Element::real);
    require_rows(w, s.ellipsoid_semi_axes, s.ellipsoid_position);
    require_rows(w, s.ellipsoid_orientation, s.ellipsoid_position);
    s.ellipsoids = s.ellipsoid_position.rows;
  }
  if (s.spheres + s.ellipsoids == 0) w.bad("scene has no bodies");
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

// Reads and validates sphere rows [first, first + count) into out (appended), chunk by chunk, into
// HostVector storage (no zero sweep; huge pages for the first touch by the reader).

void read_spheres(const SceneSource& s, hsize_t first, hsize_t count, Scene& out) {
  out.sphere_position.resize(count);
  out.sphere_radius.resize(count);
  // kReadChunkRows per thread: a chunk of 2^20 rows is only 6 + 2 blocks of 4 MiB for read_rows_f64,
  // so chunks of that size left most of a large team idle (2^26 rows on the 2×H200 host, 32 threads:
  // read stage 0.32 → 0.10 s).
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
  for (hsize_t done = 0; done < count; done += kReadChunkRows) {
    hsize_t n = std::min(kReadChunkRows, count - done);
    Vec3<double>* position = out.ellipsoid_position.data() + done;
    Vec3<double>* axes = out.ellipsoid_semi_axes.data() + done;
    std::array<double, 4>* orientation = out.ellipsoid_orientation.data() + done;
    read_rows(s.where, s.ellipsoid_position, first + done, n, H5T_NATIVE_DOUBLE, position);
    read_rows(s.where, s.ellipsoid_semi_axes, first + done, n, H5T_NATIVE_DOUBLE, axes);
    read_rows(s.where, s.ellipsoid_orientation, first + done, n, H5T_NATIVE_DOUBLE, orientation);
    for (hsize_t i = 0; i < n; ++i) {
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
  if (first < s.spheres) read_spheres(s, first, std::min(end, s.spheres) - first, scene);
  if (end > s.spheres) {
    std::size_t e_first = std::max(first, s.spheres) - s.spheres;
    read_ellipsoids(s, e_first, end - s.spheres - e_first, scene);
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
  }
  if (e > 0) {
    create_group(m.where, m.file, "/ellipsoids");
    m.ellipsoid_position = create_dataset(m.where, m.file, "/ellipsoids/position", H5T_IEEE_F64LE, {e, 3});
    m.ellipsoid_semi_axes = create_dataset(m.where, m.file, "/ellipsoids/semi_axes", H5T_IEEE_F64LE, {e, 3});
    m.ellipsoid_orientation =
        create_dataset(m.where, m.file, "/ellipsoids/orientation", H5T_IEEE_F64LE, {e, 4});
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

void SceneFileWriter::commit() {
  LibraryLock lock;
  Impl& m = *m_impl;
  if (m.committed) throw Error(fmt::format("{}: scene file committed twice", m.where.file()));
  m.sphere_position.close(m.where, "cannot close /spheres/position");
  m.sphere_radius.close(m.where, "cannot close /spheres/radius");
  m.ellipsoid_position.close(m.where, "cannot close /ellipsoids/position");
  m.ellipsoid_semi_axes.close(m.where, "cannot close /ellipsoids/semi_axes");
  m.ellipsoid_orientation.close(m.where, "cannot close /ellipsoids/orientation");
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

SceneShape read_scene_shape(const std::string& path) {
  LibraryLock lock;
  SceneSource s(path);
  open_scene(s);
  return SceneShape{s.spheres, s.ellipsoids};
}

void write_scene(const std::string& path, const Scene& scene) {
  const std::size_t n = scene.sphere_count(), e = scene.ellipsoid_count();
  if (scene.sphere_position.size() != n || scene.ellipsoid_position.size() != e ||
      scene.ellipsoid_orientation.size() != e) {
    throw Error(fmt::format("{}: write_scene: the scene's arrays differ in length", path));
  }
  SceneFileHeader header;
  header.spheres = n;
  header.ellipsoids = e;
  header.radius_low = scene.radius_low;
  header.radius_high = scene.radius_high;
  header.attributes = scene.attributes;
  SceneFileWriter writer(path, header);
  writer.write_spheres(0, scene.sphere_position, scene.sphere_radius);
  writer.write_ellipsoids(0, scene.ellipsoid_position, scene.ellipsoid_semi_axes,
                          scene.ellipsoid_orientation);
  writer.commit();
}

// ---- contact files, in phases ----------------------------------------------------------------------

// The rows are copied to the file as they are in memory: the file types are little-endian.
static_assert(std::endian::native == std::endian::little,
              "contact rows are written as raw bytes into little-endian datasets: a big-endian host "
              "needs a byte swap in write_contact_rows");
static_assert(sizeof(std::int64_t) == 8 && sizeof(double) == 8 && sizeof(float) == 4);

namespace {

// Dataset k of kContactDatasets: columns (0: rank 1) and whether it holds ids.
hsize_t contact_columns(std::size_t k) { return (k == 0 || k == 1 || k == 5) ? 0 : 3; }
bool contact_ids(std::size_t k) { return k < 2; }

std::string temp_name(const std::string& path) { return path + ".tmp." + std::to_string(::getpid()); }

// Row pointers of a Contacts in kContactDatasets order (nullptr past the fields it has).
template <class Real>
std::array<const unsigned char*, 10> contact_sources(const Contacts<Real>& c) {
  auto p = [](const auto& v) { return reinterpret_cast<const unsigned char*>(v.data()); };
  return {p(c.id_a),
          p(c.id_b),
          p(c.position_on_a),
          p(c.position_on_b),
          p(c.normal_on_b),
          p(c.distance),
          p(c.local_point_a),
          p(c.local_point_b),
          p(c.lateral_friction_dir1),
          p(c.lateral_friction_dir2)};
}

template <class Real>
bool consistent_lengths(const Contacts<Real>& c) {
  const std::size_t k = c.size();
  bool ok = c.id_b.size() == k && c.position_on_a.size() == k && c.position_on_b.size() == k &&
            c.normal_on_b.size() == k && c.distance.size() == k;
  if (c.full) {
    ok = ok && c.local_point_a.size() == k && c.local_point_b.size() == k &&
         c.lateral_friction_dir1.size() == k && c.lateral_friction_dir2.size() == k;
  }
  return ok;
}

void remove_quietly(const std::string& file) noexcept {
  std::error_code ec;
  std::filesystem::remove(file, ec);
}

}  // namespace

std::string ContactFileLayout::to_text() const {
  // One header line, one line per dataset, then the paths (each prefixed by its length: a path may
  // hold any character).
  std::string t = fmt::format("{} {} {} {}\n", rows, precision == Precision::fp32 ? 32 : 64, full ? 1 : 0,
                              datasets.size());
  for (const Dataset& d : datasets) t += fmt::format("{} {} {}\n", d.offset, d.row_bytes, d.name);
  t += fmt::format("{}\n{}\n{}\n{}", path.size(), path, temp.size(), temp);
  return t;
}

ContactFileLayout ContactFileLayout::from_text(const std::string& text) {
  ContactFileLayout l;
  std::size_t at = 0;
  auto line = [&]() {
    const std::size_t e = text.find('\n', at);
    if (e == std::string::npos) throw Error("ContactFileLayout::from_text: truncated layout");
    std::string s = text.substr(at, e - at);
    at = e + 1;
    return s;
  };
  auto counted = [&]() {
    const std::size_t n = std::stoull(line());
    if (at + n > text.size()) throw Error("ContactFileLayout::from_text: truncated layout");
    std::string s = text.substr(at, n);
    at += n;
    return s;
  };
  unsigned long long rows = 0, count = 0;
  int bits = 0, full = 0;
  if (std::sscanf(line().c_str(), "%llu %d %d %llu", &rows, &bits, &full, &count) != 4 ||
      (bits != 32 && bits != 64) || count > 10)
    throw Error("ContactFileLayout::from_text: bad header");
  l.rows = rows;
  l.precision = bits == 32 ? Precision::fp32 : Precision::fp64;
  l.full = full != 0;
  for (unsigned long long k = 0; k < count; ++k) {
    const std::string s = line();
    unsigned long long offset = 0, row_bytes = 0;
    int used = 0;
    if (std::sscanf(s.c_str(), "%llu %llu %n", &offset, &row_bytes, &used) != 2)
      throw Error("ContactFileLayout::from_text: bad dataset line");
    l.datasets.push_back({s.substr(static_cast<std::size_t>(used)), offset, row_bytes});
  }
  l.path = counted();
  if (at >= text.size() || text[at] != '\n') throw Error("ContactFileLayout::from_text: bad paths");
  ++at;
  l.temp = counted();
  return l;
}

ContactFileLayout create_contact_file(const std::string& path, std::uint64_t rows, Precision precision,
                                      bool full) {
  LibraryLock lock;
  ContactFileLayout layout;
  layout.path = path;
  layout.temp = temp_name(path);
  layout.rows = rows;
  layout.precision = precision;
  layout.full = full;
  const bool fp32 = precision == Precision::fp32;
  const hid_t real_type = fp32 ? H5T_IEEE_F32LE : H5T_IEEE_F64LE;
  const std::uint64_t real_bytes = fp32 ? 4 : 8;
  Where where(path, true);
  try {
    Handle file = create_file(where, layout.temp);
    create_group(where, file, "/contacts");
    for (std::size_t k = 0; k < (full ? 10u : 6u); ++k) {
      const hsize_t cols = contact_columns(k);
      std::vector<hsize_t> dims{rows};
      if (cols) dims.push_back(cols);
      const std::string name = kContactDatasets[k];
      Handle space = make_space(where, dims);
      Handle dcpl = creation_properties(where, H5P_DATASET_CREATE);
      // contiguous, allocated now (so it has a file offset), never filled (every row gets written)
      check(H5Pset_layout(dcpl, H5D_CONTIGUOUS), where, "cannot set dataset properties");
      check(H5Pset_alloc_time(dcpl, H5D_ALLOC_TIME_EARLY), where, "cannot set dataset properties");
      check(H5Pset_fill_time(dcpl, H5D_FILL_TIME_NEVER), where, "cannot set dataset properties");
      Handle dataset = checked(H5Dcreate2(file, name.c_str(), contact_ids(k) ? H5T_STD_I64LE : real_type,
                                          space, H5P_DEFAULT, dcpl, H5P_DEFAULT),
                               H5Dclose, where, fmt::format("{}: cannot create the dataset", name));
      ContactFileLayout::Dataset d{name, 0, contact_ids(k) ? 8 : real_bytes * (cols ? cols : 1)};
      if (rows > 0) {
        const haddr_t offset = H5Dget_offset(dataset);
        if (offset == HADDR_UNDEF) where.fail(fmt::format("{}: no file offset for the dataset's rows", name));
        d.offset = static_cast<std::uint64_t>(offset);
      }
      layout.datasets.push_back(std::move(d));
    }
    file.close(where, "cannot close (flush) the file");
  } catch (...) {
    remove_quietly(layout.temp);
    throw;
  }
  return layout;
}

template <class Real>
void write_contact_rows(const ContactFileLayout& layout, std::uint64_t first_row, const Contacts<Real>& c,
                        int threads) {
  const std::uint64_t n = c.size();
  const Precision precision = std::is_same_v<Real, float> ? Precision::fp32 : Precision::fp64;
  if (!consistent_lengths(c))
    throw Error(fmt::format("{}: write_contact_rows: the contact arrays differ in length", layout.path));
  if (precision != layout.precision || c.full != layout.full ||
      layout.datasets.size() != (layout.full ? 10u : 6u))
    throw Error(fmt::format("{}: write_contact_rows: the rows ({}, {} fields) do not match the file ({}, {})",
                            layout.path, to_string(precision), c.full ? "full" : "basic",
                            to_string(layout.precision), layout.full ? "full" : "basic"));
  if (first_row > layout.rows || n > layout.rows - first_row)
    throw Error(fmt::format("{}: write_contact_rows: rows {} + {} are outside the file's {} rows",
                            layout.path, first_row, n, layout.rows));
  if (n == 0) return;

  // Blocks of at most 4 MiB (whole rows), over every dataset, written by a team of threads.
  struct Block {
    std::size_t dataset;
    const unsigned char* src;
    std::uint64_t offset, bytes, row;
  };
  const std::array<const unsigned char*, 10> src = contact_sources(c);
  std::vector<Block> blocks;
  for (std::size_t k = 0; k < layout.datasets.size(); ++k) {
    const ContactFileLayout::Dataset& d = layout.datasets[k];
    const std::uint64_t rows_per_block = std::max<std::uint64_t>(1, (std::uint64_t(4) << 20) / d.row_bytes);
    for (std::uint64_t r = 0; r < n; r += rows_per_block) {
      const std::uint64_t m = std::min(rows_per_block, n - r);
      blocks.push_back({k, src[k] + r * d.row_bytes, d.offset + (first_row + r) * d.row_bytes,
                        m * d.row_bytes, first_row + r});
    }
  }
  const int fd = ::open(layout.temp.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) {
    const int e = errno;
    throw IoError(
        fmt::format("{}: cannot open {} for writing: {}", layout.path, layout.temp, std::strerror(e)));
  }
  std::mutex failed_mutex;
  std::optional<std::pair<std::size_t, int>> failed;  // (block, errno) of the first failed block
  const int team = threads > 0 ? threads : omp_get_max_threads();
  const std::ptrdiff_t nb = static_cast<std::ptrdiff_t>(blocks.size());
#pragma omp parallel for num_threads(team) schedule(dynamic, 1) if (nb > 1)
  for (std::ptrdiff_t b = 0; b < nb; ++b) {
    const Block& block = blocks[static_cast<std::size_t>(b)];
    std::uint64_t done = 0;
    int error = 0;
    while (done < block.bytes) {
      const ssize_t w =
          ::pwrite(fd, block.src + done, block.bytes - done, static_cast<off_t>(block.offset + done));
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) {
        error = w < 0 ? errno : ENOSPC;  // no progress: treat as a full device
        break;
      }
      done += static_cast<std::uint64_t>(w);
    }
    if (error) {
      std::lock_guard<std::mutex> guard(failed_mutex);
      if (!failed || b < static_cast<std::ptrdiff_t>(failed->first))
        failed.emplace(static_cast<std::size_t>(b), error);
    }
  }
  const int closed = ::close(fd);
  const int close_error = errno;
  if (failed) {
    const Block& block = blocks[failed->first];
    const ContactFileLayout::Dataset& d = layout.datasets[block.dataset];
    throw IoError(fmt::format("{}: {}: cannot write rows {} to {} (into {}): {}", layout.path, d.name,
                              block.row, block.row + block.bytes / d.row_bytes - 1, layout.temp,
                              std::strerror(failed->second)));
  }
  if (closed != 0) {
    throw IoError(fmt::format("{}: cannot close {} after writing rows: {}", layout.path, layout.temp,
                              std::strerror(close_error)));
  }
}

template void write_contact_rows<float>(const ContactFileLayout&, std::uint64_t, const Contacts<float>&, int);
template void write_contact_rows<double>(const ContactFileLayout&, std::uint64_t, const Contacts<double>&,
                                         int);

void commit_contact_file(const ContactFileLayout& layout, const RunInfo& info) {
  const char* precision = to_string(layout.precision);
  try {
    if (!info.precision.empty() && info.precision != precision) {
      throw Error(fmt::format("{}: write_contacts: RunInfo says precision {}, the contacts are {}",
                              layout.path, info.precision, precision));
    }
    LibraryLock lock;
    Where where(layout.path, true);
    Handle file = checked(H5Fopen(layout.temp.c_str(), H5F_ACC_RDWR, H5P_DEFAULT), H5Fclose, where,
                          fmt::format("cannot reopen {}", layout.temp));
    Attributes attributes;
    attributes["precision"] = std::string(precision);
    attributes["backend"] = info.backend;
    attributes["ranks"] = std::int64_t{info.ranks};
    attributes["bodies"] = static_cast<std::int64_t>(info.bodies);
    attributes["contacts"] = static_cast<std::int64_t>(layout.rows);
    attributes["cell_size"] = info.cell_size;
    attributes["software_version"] = std::string(kSoftwareVersion);
    attributes["input"] = info.input;
    for (const StageTime& stage : info.times) {  // a stage named twice: the times add up
      auto [it, inserted] = attributes.try_emplace("time_" + stage.name, stage.seconds);
      if (!inserted) it->second = std::get<double>(it->second) + stage.seconds;
    }
    {
      Handle root = checked(H5Gopen2(file, "/", H5P_DEFAULT), H5Gclose, where, "cannot open the root group");
      for (const auto& [name, value] : attributes) write_attribute(where, root, name, value);
    }
    file.close(where, "cannot close (flush) the file");
    if (std::rename(layout.temp.c_str(), layout.path.c_str()) != 0) {
      const int error = errno;
      throw IoError(
          fmt::format("{}: cannot rename {} over it: {}", layout.path, layout.temp, std::strerror(error)));
    }
  } catch (...) {
    remove_quietly(layout.temp);
    throw;
  }
}

void discard_contact_file(const ContactFileLayout& layout) noexcept { remove_quietly(layout.temp); }

template <class Real>
void write_contacts(const std::string& path, const Contacts<Real>& c, const RunInfo& info, int threads) {
  const char* precision = std::is_same_v<Real, float> ? "fp32" : "fp64";
  if (!consistent_lengths(c))
    throw Error(fmt::format("{}: write_contacts: the contact arrays differ in length", path));
  if (!info.precision.empty() && info.precision != precision) {
    throw Error(fmt::format("{}: write_contacts: RunInfo says precision {}, the contacts are {}", path,
                            info.precision, precision));
  }
  const ContactFileLayout layout = create_contact_file(
      path, c.size(), std::is_same_v<Real, float> ? Precision::fp32 : Precision::fp64, c.full);
  try {
    write_contact_rows(layout, 0, c, threads);
  } catch (...) {
    discard_contact_file(layout);
    throw;
  }
  commit_contact_file(layout, info);
}

template void write_contacts<float>(const std::string&, const Contacts<float>&, const RunInfo&, int);
template void write_contacts<double>(const std::string&, const Contacts<double>&, const RunInfo&, int);

ContactFile read_contacts(const std::string& path) {
  LibraryLock lock;
  Where where(path, false);
  Handle file = open_file_for_reading(where);
  ContactFile out;
  out.attributes = read_root_attributes(where, file);
  auto precision = out.attributes.find("precision");
  if (precision == out.attributes.end()) where.bad("root attribute precision is missing");
  const auto* precision_text = std::get_if<std::string>(&precision->second);
  if (precision_text == nullptr || (*precision_text != "fp32" && *precision_text != "fp64"))
    where.bad("root attribute precision is not \"fp32\" or \"fp64\"");
  out.precision = *precision_text;

  if (!group_exists(where, file, "/contacts")) where.bad("/contacts: missing group");
  Dataset id_a = open_dataset(where, file, "/contacts/id_a", 0, Element::integer);
  Dataset id_b = open_dataset(where, file, "/contacts/id_b", 0, Element::integer);
  require_rows(where, id_b, id_a);
  const hsize_t k = id_a.rows;
  Contacts<double>& c = out.contacts;
  c.id_a.resize(k);
  c.id_b.resize(k);
  read_rows(where, id_a, 0, k, H5T_NATIVE_INT64, c.id_a.data());
  read_rows(where, id_b, 0, k, H5T_NATIVE_INT64, c.id_b.data());

  auto read_real = [&](const char* name, hsize_t cols, auto& vector) {
    Dataset d = open_dataset(where, file, name, cols, Element::real);
    require_rows(where, d, id_a);
    vector.resize(k);
    read_rows(where, d, 0, k, H5T_NATIVE_DOUBLE, vector.data());
  };
  read_real("/contacts/position_on_a", 3, c.position_on_a);
  read_real("/contacts/position_on_b", 3, c.position_on_b);
  read_real("/contacts/normal_on_b", 3, c.normal_on_b);
  read_real("/contacts/distance", 0, c.distance);

  const char* optional[] = {"/contacts/local_point_a", "/contacts/local_point_b",
                            "/contacts/lateral_friction_dir1", "/contacts/lateral_friction_dir2"};
  int present = 0;
  for (const char* name : optional) present += path_exists(where, file, name) ? 1 : 0;
  if (present != 0 && present != 4)
    where.bad(
        "/contacts: the optional datasets (local points, friction directions) must be all present or none");
  c.full = present == 4;
  if (c.full) {
    read_real(optional[0], 3, c.local_point_a);
    read_real(optional[1], 3, c.local_point_b);
    read_real(optional[2], 3, c.lateral_friction_dir1);
    read_real(optional[3], 3, c.lateral_friction_dir2);
  }
  return out;
}

// ---- raw helpers (tests, tools) -----------------------------------------------------------------

namespace {
Handle open_or_create(const Where& where) {
  std::error_code ec;
  if (std::filesystem::exists(where.file(), ec)) {
    return checked(H5Fopen(where.file().c_str(), H5F_ACC_RDWR, H5P_DEFAULT), H5Fclose, where,
                   "cannot open the file for writing");
  }
  return create_file(where, where.file());
}
}  // namespace

void write_raw_dataset(const std::string& path, const std::string& dataset, RawType type,
                       const std::vector<std::uint64_t>& dims, std::span<const double> values) {
  LibraryLock lock;
  Where where(path, true);
  std::uint64_t product = 1;
  for (std::uint64_t d : dims) product *= d;
  if (product != values.size())
    throw Error(
        fmt::format("{}: {}: {} values for shape of {} elements", path, dataset, values.size(), product));
  hid_t file_type = H5T_IEEE_F64LE;
  switch (type) {
    case RawType::float64:
      file_type = H5T_IEEE_F64LE;
      break;
    case RawType::float32:
      file_type = H5T_IEEE_F32LE;
      break;
    case RawType::int32:
      file_type = H5T_STD_I32LE;
      break;
    case RawType::int64:
      file_type = H5T_STD_I64LE;
      break;
  }
  Handle file = open_or_create(where);
  {
    std::vector<hsize_t> shape(dims.begin(), dims.end());
    Handle d = create_dataset(where, file, dataset, file_type, shape);
    if (!values.empty()) {
      check(H5Dwrite(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()), where,
            fmt::format("{}: cannot write", dataset));
    }
  }
  file.close(where, "cannot close (flush) the file");
}

void write_raw_attribute(const std::string& path, const std::string& name, const AttrValue& value) {
  LibraryLock lock;
  Where where(path, true);
  Handle file = open_or_create(where);
  {
    Handle root = checked(H5Gopen2(file, "/", H5P_DEFAULT), H5Gclose, where, "cannot open the root group");
    htri_t exists = H5Aexists(root, name.c_str());
    if (exists < 0) where.fail(fmt::format("cannot look up root attribute {}", name));
    if (exists > 0)
      check(H5Adelete(root, name.c_str()), where, fmt::format("cannot replace root attribute {}", name));
    write_attribute(where, root, name, value);
  }
  file.close(where, "cannot close (flush) the file");
}

std::optional<DatasetInfo> inspect_dataset(const std::string& path, const std::string& dataset) {
  LibraryLock lock;
  Where where(path, false);
  Handle file = open_file_for_reading(where);
  if (!path_exists(where, file, dataset)) return std::nullopt;
  if (object_type(where, file, dataset) != H5I_DATASET)
    where.bad(fmt::format("{} is not a dataset", dataset));
  Handle d = checked(H5Dopen2(file, dataset.c_str(), H5P_DEFAULT), H5Dclose, where,
                     fmt::format("{}: cannot open the dataset", dataset));
  Handle type = checked(H5Dget_type(d), H5Tclose, where, fmt::format("{}: cannot read the type", dataset));
  Handle space = checked(H5Dget_space(d), H5Sclose, where, fmt::format("{}: cannot read the shape", dataset));
  DatasetInfo info;
  std::size_t bits = H5Tget_size(type) * 8;
  switch (H5Tget_class(type)) {
    case H5T_FLOAT:
      info.type = fmt::format("float{}", bits);
      break;
    case H5T_INTEGER:
      info.type = fmt::format("{}int{}", H5Tget_sign(type) == H5T_SGN_NONE ? "u" : "", bits);
      break;
    default:
      info.type = "other";
      break;
  }
  int rank = H5Sget_simple_extent_ndims(space);
  if (rank < 0) where.fail(fmt::format("{}: cannot read the shape", dataset));
  std::vector<hsize_t> dims(static_cast<std::size_t>(rank));
  if (rank > 0 && H5Sget_simple_extent_dims(space, dims.data(), nullptr) < 0)
    where.fail(fmt::format("{}: cannot read the shape", dataset));
  info.dims.assign(dims.begin(), dims.end());
  return info;
}

std::vector<unsigned char> read_dataset_bytes(const std::string& path, const std::string& dataset) {
  LibraryLock lock;
  Where where(path, false);
  Handle file = open_file_for_reading(where);
  if (!path_exists(where, file, dataset)) where.bad(fmt::format("{}: missing dataset", dataset));
  Handle d = checked(H5Dopen2(file, dataset.c_str(), H5P_DEFAULT), H5Dclose, where,
                     fmt::format("{}: cannot open the dataset", dataset));
  Handle type = checked(H5Dget_type(d), H5Tclose, where, fmt::format("{}: cannot read the type", dataset));
  Handle space = checked(H5Dget_space(d), H5Sclose, where, fmt::format("{}: cannot read the shape", dataset));
  hssize_t points = H5Sget_simple_extent_npoints(space);
  if (points < 0) where.fail(fmt::format("{}: cannot read the shape", dataset));
  std::vector<unsigned char> bytes(static_cast<std::size_t>(points) * H5Tget_size(type));
  if (!bytes.empty())
    check(H5Dread(d, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, bytes.data()), where,
          fmt::format("{}: cannot read", dataset));
  return bytes;
}

}  // namespace cg
