// attributes.cpp: reading and writing root attributes (see attributes.hpp).
#include "io/attributes.hpp"

#include <fmt/format.h>

#include <cstdint>
#include <cstring>

namespace cg::h5 {

// ---- attributes ------------------------------------------------------------------------------

namespace {

herr_t collect_attribute_name(hid_t, const char* name, const H5A_info_t*, void* data) {
  static_cast<std::vector<std::string>*>(data)->emplace_back(name);
  return 0;
}

}  // namespace

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

}  // namespace cg::h5
