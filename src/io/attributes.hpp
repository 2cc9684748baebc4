#pragma once
// Internal to src/io: root attributes (scalars: int64, float64, strings).
#include <hdf5.h>

#include <optional>
#include <string>
#include <vector>

#include "io/hdf5_handle.hpp"
#include "scene.hpp"

namespace cg::h5 {

std::vector<std::string> attribute_names(const Where& where, hid_t object);
// A scalar (or one-element) integer, float or string attribute; nullopt for other kinds.
std::optional<AttrValue> read_attribute(const Where& where, hid_t object, const std::string& name);
// Every root attribute read_attribute can read.
Attributes read_root_attributes(const Where& where, hid_t file);
// A scalar attribute: int64 → STD_I64LE, double → IEEE_F64LE, string → variable-length UTF-8.
void write_attribute(const Where& where, hid_t object, const std::string& name, const AttrValue& value);

}  // namespace cg::h5
