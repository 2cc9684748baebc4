// datasets.cpp: typed, shape-checked datasets and their rows (see datasets.hpp).
#include "io/datasets.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string_view>
#include <vector>

#include "io/attributes.hpp"

namespace cg::h5 {

ReadMode read_mode() {
  const char* knob = std::getenv("CONTACTGRID_IO_READ");
  const std::string_view v = knob ? knob : "";
  if (v.empty() || v == "direct") return ReadMode::direct;
  if (v == "hdf5") return ReadMode::hdf5;
  throw UsageError(fmt::format("CONTACTGRID_IO_READ={}: expected direct or hdf5", v));
}

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
  // (standard_number: IEEE floats and unpadded integers only; HDF5 converts other encodings bit by bit)
  if (element == Element::real &&
      !(type_class == H5T_FLOAT && (size == 4 || size == 8) && standard_number(type)))
    where.bad(fmt::format("{}: element type is {}; expected float64 or float32", name, type_text(type)));
  if (element == Element::integer && !(type_class == H5T_INTEGER && standard_number(type)))
    where.bad(fmt::format("{}: element type is {}; expected int64", name, type_text(type)));
  d.element_size = size;

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
  check_storage(where, d.id, name, declared_bytes(where, name, dims, size));
  return d;
}

std::uint64_t declared_bytes(const Where& where, const std::string& name, const std::vector<hsize_t>& dims,
                             std::size_t element_size) {
  std::uint64_t bytes = element_size;
  for (hsize_t d : dims) {
    if (d != 0 && bytes > std::numeric_limits<std::uint64_t>::max() / d)
      where.bad(fmt::format("{}: shape {} is too large (damaged file?)", name, shape_text(dims)));
    bytes *= d;
  }
  return bytes;
}

void check_storage(const Where& where, hid_t dataset, const std::string& name, std::uint64_t declared_bytes) {
  std::error_code ec;
  const std::uint64_t file_bytes = std::filesystem::file_size(where.file(), ec);
  if (ec) where.bad(fmt::format("{}: cannot get the file's size: {}", name, ec.message()));
  Handle dcpl = checked(H5Dget_create_plist(dataset), H5Pclose, where,
                        fmt::format("{}: cannot read the storage properties", name));
  const int external = H5Pget_external_count(dcpl);
  if (external != 0) where.bad(fmt::format("{}: data in external files is not read", name));
  const H5D_layout_t layout = H5Pget_layout(dcpl);
  if (layout == H5D_CONTIGUOUS) {
    const haddr_t offset = H5Dget_offset(dataset);
    if (declared_bytes > file_bytes ||
        (offset != HADDR_UNDEF && declared_bytes > 0 && offset > file_bytes - declared_bytes)) {
      where.bad(
          fmt::format("{}: its {} bytes of data do not fit in the file's {} bytes (truncated or damaged?)",
                      name, declared_bytes, file_bytes));
    }
    return;
  }
  if (layout != H5D_CHUNKED && layout != H5D_COMPACT)
    where.bad(fmt::format("{}: storage layout {} is not read (contiguous, chunked or compact only)", name,
                          static_cast<int>(layout)));
  const hsize_t stored = H5Dget_storage_size(dataset);
  // Compact data is the raw values themselves, inside the object header (no filters): exactly the
  // declared bytes. libhdf5 1.10.8 copies the declared bytes from the stored buffer without checking
  // its size (a damaged header with 0 bytes stored made H5Dread copy from a null pointer).
  if (layout == H5D_COMPACT && stored != declared_bytes) {
    where.bad(fmt::format("{}: compact data of {} bytes where its shape and type need {} (damaged?)", name,
                          stored, declared_bytes));
  }
  if (stored > file_bytes || declared_bytes / kMaxExpansion > file_bytes) {
    where.bad(fmt::format("{}: {} bytes of data ({} stored) for a file of {} bytes (damaged?)", name,
                          declared_bytes, stored, file_bytes));
  }
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
// threads when the dataset is stored as plain bytes: contiguous layout (no chunks, no filters, no
// external file), allocated, IEEE float64 or float32 little-endian (float32 rows widened to double by
// the thread that read them, as H5Dread converts them). HDF5's own read runs on one thread (well
// below the page cache's bandwidth); anything else goes through it, and so does everything with
// CONTACTGRID_IO_READ=hdf5.
void read_rows_f64(const Where& where, const Dataset& d, hsize_t first, hsize_t count, double* out) {
  if (count == 0) return;
  static_assert(std::endian::native == std::endian::little, "direct reads assume a little-endian host");
  std::uint64_t element = 0;  // 8 or 4: the file's float64 or float32 bytes; 0: through HDF5
  haddr_t base = HADDR_UNDEF;
  if (read_mode() == ReadMode::direct) {
    Handle dcpl(H5Dget_create_plist(d.id), H5Pclose);
    Handle type(H5Dget_type(d.id), H5Tclose);
    if (dcpl.get() >= 0 && type.get() >= 0 && H5Pget_layout(dcpl) == H5D_CONTIGUOUS &&
        H5Pget_external_count(dcpl) == 0) {
      element = H5Tequal(type, H5T_IEEE_F64LE) > 0 ? 8 : H5Tequal(type, H5T_IEEE_F32LE) > 0 ? 4 : 0;
    }
    if (element != 0) base = H5Dget_offset(d.id);
    if (base == HADDR_UNDEF) element = 0;
  }
  if (element == 0) {
    read_rows(where, d, first, count, H5T_NATIVE_DOUBLE, out);
    return;
  }
  const std::uint64_t values_per_row = std::max<hsize_t>(d.cols, 1);
  const std::uint64_t offset = std::uint64_t(base) + std::uint64_t(first) * values_per_row * element;
  const std::uint64_t bytes = std::uint64_t(count) * values_per_row * element;
  const int fd = ::open(where.file().c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) where.bad(fmt::format("{}: cannot open for reading: {}", d.name, std::strerror(errno)));
  constexpr std::uint64_t kBlock = std::uint64_t(4) << 20;  // file bytes a block (a multiple of 8)
  const auto blocks = static_cast<std::int64_t>((bytes + kBlock - 1) / kBlock);
  std::atomic<int> error{0};
  const int threads = blocks > 1 ? omp_get_max_threads() : 1;
#pragma omp parallel num_threads(threads) if (threads > 1)
  {
    std::vector<float> narrow(element == 4 ? kBlock / 4 : 0);  // a float32 block before it is widened
#pragma omp for schedule(dynamic, 1)
    for (std::int64_t b = 0; b < blocks; ++b) {
      const std::uint64_t at = std::uint64_t(b) * kBlock, len = std::min(kBlock, bytes - at);
      auto* dst = element == 8 ? reinterpret_cast<unsigned char*>(out) + at
                               : reinterpret_cast<unsigned char*>(narrow.data());
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
      if (element == 4 && done == len) std::copy(narrow.data(), narrow.data() + len / 4, out + at / 4);
    }
  }
  ::close(fd);
  if (const int e = error.load()) {
    where.bad(
        fmt::format("{}: cannot read rows {} to {}: {}", d.name, first, first + count - 1,
                    e == EIO ? "the file ends before the dataset does (truncated?)" : std::strerror(e)));
  }
}

void require_rows(const Where& where, const Dataset& d, const Dataset& reference) {
  if (d.rows != reference.rows)
    where.bad(fmt::format("{}: {} rows, but {} has {}", d.name, d.rows, reference.name, reference.rows));
}

}  // namespace cg::h5
