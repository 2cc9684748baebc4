// attributes.cpp: reading and writing root attributes (see attributes.hpp).
#include "io/attributes.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cstdint>
#include <cstring>

#include "io/raw_attributes.hpp"

namespace cg::h5 {

// ---- attributes ------------------------------------------------------------------------------

bool standard_number(hid_t type) {
  switch (H5Tget_class(type)) {
    case H5T_INTEGER: {
      const std::size_t size = H5Tget_size(type);
      return (size == 1 || size == 2 || size == 4 || size == 8) && H5Tget_precision(type) == 8 * size &&
             H5Tget_offset(type) == 0;
    }
    case H5T_FLOAT:
      for (hid_t standard : {H5T_IEEE_F32LE, H5T_IEEE_F32BE, H5T_IEEE_F64LE, H5T_IEEE_F64BE}) {
        if (H5Tequal(type, standard) > 0) return true;
      }
      return false;
    default:
      return false;
  }
}

namespace {

// HDF5's own read, for headers raw_attributes does not follow (dense storage, shared messages).
std::optional<double> hdf5_number_attribute(const Where& where, hid_t object, const std::string& name) {
  const std::string what = fmt::format("root attribute {}: cannot read", name);
  const htri_t exists = H5Aexists(object, name.c_str());
  if (exists < 0) where.fail(what);
  if (exists == 0) return std::nullopt;
  Handle attr = checked(H5Aopen(object, name.c_str(), H5P_DEFAULT), H5Aclose, where, what);
  Handle space = checked(H5Aget_space(attr), H5Sclose, where, what);
  Handle type = checked(H5Aget_type(attr), H5Tclose, where, what);
  if (H5Tget_class(type) == H5T_STRING)
    where.bad(fmt::format("root attribute {} is a string; expected a number", name));
  if (!standard_number(type))
    where.bad(fmt::format("root attribute {} is a {}; expected a number (float or integer)", name,
                          type_text(type)));
  const hssize_t points = H5Sget_simple_extent_npoints(space);
  if (points != 1)
    where.bad(fmt::format("root attribute {} holds {} values; expected one number", name, points));
  double value = 0;
  check(H5Aread(attr, H5T_NATIVE_DOUBLE, &value), where, what);
  return value;
}

}  // namespace

RawAttributes root_attributes(const Where& where, hid_t file) {
  Handle root = checked(H5Gopen2(file, "/", H5P_DEFAULT), H5Gclose, where, "cannot open the root group");
  RawAttributes raw = raw_attributes(where.file(), file, root);
  if (raw.status == RawAttributes::Status::damaged)
    where.bad("the root group's header is damaged: its attributes cannot be decoded");
  return raw;
}

bool has_root_attribute(const Where& where, hid_t file, const RawAttributes& raw, const std::string& name) {
  if (raw.status == RawAttributes::Status::ok) return raw.names.count(name) != 0;
  Handle root = checked(H5Gopen2(file, "/", H5P_DEFAULT), H5Gclose, where, "cannot open the root group");
  const htri_t exists = H5Aexists(root, name.c_str());
  if (exists < 0) where.fail(fmt::format("cannot look up root attribute {}", name));
  return exists > 0;
}

std::optional<double> number_attribute(const Where& where, hid_t file, const RawAttributes& raw,
                                       const std::string& name) {
  if (raw.status != RawAttributes::Status::ok) {
    Handle root = checked(H5Gopen2(file, "/", H5P_DEFAULT), H5Gclose, where, "cannot open the root group");
    return hdf5_number_attribute(where, root, name);
  }
  if (raw.names.count(name) == 0) return std::nullopt;
  const auto it = raw.values.find(name);
  if (it == raw.values.end())
    where.bad(fmt::format("root attribute {} is not one number (an integer or an IEEE float)", name));
  if (std::holds_alternative<std::string>(it->second))
    where.bad(fmt::format("root attribute {} is a string; expected a number", name));
  if (const auto* i = std::get_if<std::int64_t>(&it->second)) return static_cast<double>(*i);
  return std::get<double>(it->second);
}

std::optional<std::string> string_attribute(const Where& where, hid_t file, const RawAttributes& raw,
                                            const std::string& name) {
  if (raw.status == RawAttributes::Status::ok) {
    if (raw.names.count(name) == 0) return std::nullopt;
    const auto it = raw.values.find(name);
    const auto* text = it == raw.values.end() ? nullptr : std::get_if<std::string>(&it->second);
    if (text == nullptr) where.bad(fmt::format("root attribute {} is not a string", name));
    return *text;
  }
  // A header raw_attributes does not follow (dense or shared storage; not a damaged one): HDF5 reads it.
  Handle root = checked(H5Gopen2(file, "/", H5P_DEFAULT), H5Gclose, where, "cannot open the root group");
  const std::string what = fmt::format("root attribute {}: cannot read", name);
  const htri_t exists = H5Aexists(root, name.c_str());
  if (exists < 0) where.fail(what);
  if (exists == 0) return std::nullopt;
  Handle attr = checked(H5Aopen(root, name.c_str(), H5P_DEFAULT), H5Aclose, where, what);
  Handle space = checked(H5Aget_space(attr), H5Sclose, where, what);
  Handle type = checked(H5Aget_type(attr), H5Tclose, where, what);
  if (H5Tget_class(type) != H5T_STRING || H5Sget_simple_extent_npoints(space) != 1)
    where.bad(fmt::format("root attribute {} is not a string", name));
  if (H5Tis_variable_str(type) > 0) {
    Handle memory = string_type(where);
    char* text = nullptr;
    check(H5Aread(attr, memory, &text), where, what);
    std::string value = text ? text : "";
    H5free_memory(text);
    return value;
  }
  std::string value(H5Tget_size(type), '\0');
  Handle memory = checked(H5Tcopy(type), H5Tclose, where, what);
  check(H5Aread(attr, memory, value.data()), where, what);
  return value.substr(0, value.find('\0'));
}

Attributes other_attributes(const RawAttributes& raw, std::initializer_list<const char*> skip) {
  if (raw.status != RawAttributes::Status::ok) return {};
  Attributes attributes = raw.values;
  for (const char* name : skip) attributes.erase(name);
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

}  // namespace cg::h5
