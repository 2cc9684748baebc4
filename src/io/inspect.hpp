#pragma once
// Any dataset of an HDF5 file as stored (compare, tests), and raw writers for tests and tools.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "scene/scene.hpp"

namespace cg {

// Low-level helpers for tests and tools that must produce files the writers above refuse to make
// (wrong element types, shapes, empty datasets). They write in place (no temporary): the file is
// created if missing, else opened read-write; intermediate groups are created; `values` (row-major,
// converted by HDF5 to `type`) must hold the product of `dims` values. Throw IoError.
enum class RawType { float64, float32, int32, int64 };
void write_raw_dataset(const std::string& path, const std::string& dataset, RawType type,
                       const std::vector<std::uint64_t>& dims, std::span<const double> values);
void write_raw_attribute(const std::string& path, const std::string& name, const AttrValue& value);

// Element type ("float64", "float32", "int64", "int32", … "uint8", or "other") and shape of a dataset;
// nullopt when the path does not exist. InputError when the file cannot be read.
struct DatasetInfo {
  std::string type;
  std::vector<std::uint64_t> dims;
};
std::optional<DatasetInfo> inspect_dataset(const std::string& path, const std::string& dataset);

// A dataset's elements as stored in the file (its own type, row-major, no conversion): what the
// byte-for-byte comparisons of runs look at. InputError when missing or unreadable.
std::vector<unsigned char> read_dataset_bytes(const std::string& path, const std::string& dataset);

}  // namespace cg
