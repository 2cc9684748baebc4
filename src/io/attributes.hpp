#pragma once
// Internal to src/io: root attributes (scalars: int64, float64, strings).
#include <hdf5.h>

#include <initializer_list>
#include <optional>
#include <string>
#include <vector>

#include "io/hdf5_handle.hpp"
#include "io/raw_attributes.hpp"
#include "scene/scene.hpp"

namespace cg::h5 {

// An integer of 1, 2, 4 or 8 bytes without padding, or an IEEE float32/float64 (either byte order):
// what HDF5 converts without surprises.
bool standard_number(hid_t type);

// The root group's attributes, decoded from the file's bytes (raw_attributes.hpp); InputError naming
// the file when its header is damaged (HDF5 1.10.8 would crash decoding it).
RawAttributes root_attributes(const Where& where, hid_t file);

// Whether the root attribute exists (HDF5 is asked only where raw.status is unsupported).
bool has_root_attribute(const Where& where, hid_t file, const RawAttributes& raw, const std::string& name);

// A root attribute docs/FORMAT.md §1 gives meaning to (radius_low, radius_high): nullopt when absent; a
// string, another type or more than one value is an InputError naming it.
std::optional<double> number_attribute(const Where& where, hid_t file, const RawAttributes& raw,
                                       const std::string& name);

// A root attribute that is one string (quaternion_order): nullopt when absent; another type is an
// InputError naming it.
std::optional<std::string> string_attribute(const Where& where, hid_t file, const RawAttributes& raw,
                                            const std::string& name);

// The other root attributes (generator parameters, run record), except those named in `skip`: they
// mean nothing to the readers, so HDF5 is never asked for them; what raw_attributes could decode
// (nothing unless raw.status is ok).
Attributes other_attributes(const RawAttributes& raw, std::initializer_list<const char*> skip = {});

// A scalar attribute: int64 → STD_I64LE, double → IEEE_F64LE, string → variable-length UTF-8.
void write_attribute(const Where& where, hid_t object, const std::string& name, const AttrValue& value);

}  // namespace cg::h5
