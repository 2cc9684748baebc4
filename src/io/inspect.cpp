// inspect.cpp: datasets as stored, raw writers (see inspect.hpp).
#include "io/inspect.hpp"

#include <fmt/format.h>
#include <hdf5.h>

#include <filesystem>

#include "io/attributes.hpp"
#include "io/datasets.hpp"
#include "io/hdf5_handle.hpp"

namespace cg {

using namespace h5;  // NOLINT: the io layer's own helpers

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
  check_object_header(where, file, dataset, dataset);
  Handle d = checked(H5Dopen2(file, dataset.c_str(), H5P_DEFAULT), H5Dclose, where,
                     fmt::format("{}: cannot open the dataset", dataset));
  Handle type = checked(H5Dget_type(d), H5Tclose, where, fmt::format("{}: cannot read the type", dataset));
  Handle space = checked(H5Dget_space(d), H5Sclose, where, fmt::format("{}: cannot read the shape", dataset));
  // Numbers only (what docs/FORMAT.md §2 stores): other types go through conversions that read the global
  // heap (variable-length) or references, which a damaged file can make crash.
  if (!standard_number(type))
    where.bad(fmt::format("{}: element type is {}; expected an integer or float", dataset, type_text(type)));
  const int rank = H5Sget_simple_extent_ndims(space);
  if (rank < 0) where.fail(fmt::format("{}: cannot read the shape", dataset));
  std::vector<hsize_t> dims(static_cast<std::size_t>(rank));
  if (rank > 0 && H5Sget_simple_extent_dims(space, dims.data(), nullptr) < 0)
    where.fail(fmt::format("{}: cannot read the shape", dataset));
  const std::uint64_t size = declared_bytes(where, dataset, dims, H5Tget_size(type));
  check_storage(where, d, dataset, size);
  std::vector<unsigned char> bytes(size);
  if (!bytes.empty())
    check(H5Dread(d, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, bytes.data()), where,
          fmt::format("{}: cannot read", dataset));
  return bytes;
}

}  // namespace cg
