// hdf5_handle.cpp: the RAII layer over the HDF5 C API (see hdf5_handle.hpp for the invariants).
#include "io/hdf5_handle.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "io/raw_attributes.hpp"

namespace cg::h5 {

namespace {

std::mutex g_hdf5_mutex;

herr_t take_innermost_error(unsigned n, const H5E_error2_t* error, void* data) {
  if (n == 0 && error != nullptr && error->desc != nullptr) *static_cast<std::string*>(data) = error->desc;
  return 0;
}

// The most specific message on HDF5's error stack (then cleared); "" when there is none.

}  // namespace

LibraryLock::LibraryLock() : m_lock(g_hdf5_mutex) {
  static const bool quiet = [] {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    return true;
  }();
  (void)quiet;
}

std::string hdf5_detail() {
  std::string detail;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, take_innermost_error, &detail);
  H5Eclear2(H5E_DEFAULT);
  return detail;
}

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
    {  // the group searched for the next component must be sound (raw_attributes.hpp: damaged_group)
      const std::string parent = prefix.substr(0, std::max<std::size_t>(1, prefix.rfind('/')));
      if (parent != "/") check_object_header(where, file, parent, path);
      Handle group = checked(H5Oopen(file, parent.c_str(), H5P_DEFAULT), H5Oclose, where,
                             fmt::format("{}: cannot open {}", path, parent));
      if (H5Iget_type(group) != H5I_GROUP) return false;
      const std::string damage = damaged_group(where.file(), file, group);
      if (!damage.empty()) where.bad(fmt::format("{}: the group {} is damaged: {}", path, parent, damage));
    }
    htri_t exists = H5Lexists(file, prefix.c_str(), H5P_DEFAULT);
    if (exists < 0) where.fail(fmt::format("{}: cannot look up {}", path, prefix));
    if (exists == 0) return false;
  }
  return true;
}

void check_object_header(const Where& where, hid_t file, const std::string& path, const std::string& what) {
  const std::string damage = damaged_object(where.file(), file, path);
  if (damage.empty()) return;
  if (what == path) where.bad(fmt::format("{}: damaged: {}", path, damage));
  where.bad(fmt::format("{}: {} is damaged: {}", what, path, damage));
}

H5I_type_t object_type(const Where& where, hid_t file, const std::string& path) {
  check_object_header(where, file, path, path);
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

// ---- writing ---------------------------------------------------------------------------------

Handle creation_properties(const Where& where, hid_t plist_class) {
  Handle plist = checked(H5Pcreate(plist_class), H5Pclose, where, "cannot create a property list");
  check(H5Pset_obj_track_times(plist, 0), where, "cannot set object properties");
  return plist;
}

Handle create_file(const Where& where, const std::string& name) {
  check_output_directory(where.file());
  Handle fcpl = creation_properties(where, H5P_FILE_CREATE);
  const hid_t id = H5Fcreate(name.c_str(), H5F_ACC_TRUNC, fcpl, H5P_DEFAULT);
  if (id < 0) {
    // HDF5's message names the temporary and its internal flags; only the system's reason is the user's.
    const std::string detail = hdf5_detail();
    const std::size_t at = detail.find("error message = '");
    std::string reason = "the file cannot be created";
    if (at != std::string::npos) {
      const std::size_t from = at + 17, to = detail.find('\'', from);
      reason = detail.substr(from, to == std::string::npos ? std::string::npos : to - from);
    }
    throw IoError(fmt::format("{}: cannot write: {}", where.file(), reason));
  }
  return Handle(id, H5Fclose);
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

}  // namespace cg::h5
