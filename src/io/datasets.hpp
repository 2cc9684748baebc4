#pragma once
// Internal to src/io: opening a dataset of docs/FORMAT.md §1/§2 with its type and shape checked, and reading
// rows of it (through HDF5, or by pread for plain float64 storage).
#include <hdf5.h>

#include <cstdint>
#include <string>
#include <vector>

#include "io/hdf5_handle.hpp"

namespace cg::h5 {

// A dataset whose shape is (rows) or (rows, cols), element type checked.
struct Dataset {
  std::string name;
  Handle id;
  hsize_t rows = 0;
  hsize_t cols = 0;              // 0: rank 1
  std::size_t element_size = 0;  // bytes of one element in the file
};

enum class Element { real, integer };

// Opens `name` (InputError naming file and dataset when missing, of another type class or shape).
Dataset open_dataset(const Where& where, hid_t file, const std::string& name, hsize_t cols, Element element);

// Checks, before anything is allocated or read, that `dataset` (of `declared_bytes` = elements ×
// element size) can be read from this file: not in external files nor virtual; contiguous data
// inside the file; chunked or compact data no larger than the file, and its elements no more than
// kMaxExpansion times the file's size (a damaged shape must not become an allocation). InputError
// naming the dataset otherwise.
inline constexpr std::uint64_t kMaxExpansion = 1024;
void check_storage(const Where& where, hid_t dataset, const std::string& name, std::uint64_t declared_bytes);

// elements × element size, or InputError when it overflows 64 bits.
std::uint64_t declared_bytes(const Where& where, const std::string& name, const std::vector<hsize_t>& dims,
                             std::size_t element_size);

// InputError unless d has as many rows as reference.
void require_rows(const Where& where, const Dataset& d, const Dataset& reference);

// How read_rows_f64 reads plain storage: CONTACTGRID_IO_READ=hdf5 sends every read through H5Dread
// (one thread; the former path, for comparison), unset or `direct` by pread; any other value is refused
// (UsageError).
enum class ReadMode { direct, hdf5 };
ReadMode read_mode();

// Rows [first, first + count) of d into out (count·max(cols,1) values of mem_type).
void read_rows(const Where& where, const Dataset& d, hsize_t first, hsize_t count, hid_t mem_type, void* out);

// The same rows into float64 memory; plain contiguous float64 or float32 little-endian storage is read
// by pread on all threads (float32 widened), anything else through read_rows.
void read_rows_f64(const Where& where, const Dataset& d, hsize_t first, hsize_t count, double* out);

}  // namespace cg::h5
