#pragma once
// Internal to src/io: opening a dataset of CONTRACT §1/§2 with its type and shape checked, and reading
// rows of it (through HDF5, or by pread for plain float64 storage).
#include <hdf5.h>

#include <string>

#include "io/hdf5_handle.hpp"

namespace cg::h5 {

// A dataset whose shape is (rows) or (rows, cols), element type checked.
struct Dataset {
  std::string name;
  Handle id;
  hsize_t rows = 0;
  hsize_t cols = 0;  // 0: rank 1
};

enum class Element { real, integer };

// Opens `name` (InputError naming file and dataset when missing, of another type class or shape).
Dataset open_dataset(const Where& where, hid_t file, const std::string& name, hsize_t cols, Element element);

// InputError unless d has as many rows as reference.
void require_rows(const Where& where, const Dataset& d, const Dataset& reference);

// Rows [first, first + count) of d into out (count·max(cols,1) values of mem_type).
void read_rows(const Where& where, const Dataset& d, hsize_t first, hsize_t count, hid_t mem_type, void* out);

// The same rows into float64 memory; plain contiguous float64 little-endian storage is read by pread
// on all threads, anything else through read_rows.
void read_rows_f64(const Where& where, const Dataset& d, hsize_t first, hsize_t count, double* out);

}  // namespace cg::h5
