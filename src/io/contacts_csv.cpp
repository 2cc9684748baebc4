// contacts_csv.cpp: the CSV copy of the contacts (see contacts_csv.hpp).
#include "io/contacts_csv.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iterator>

#include "errors.hpp"
#include "io/hdf5_handle.hpp"

namespace cg {

template <class Real>
void write_contacts_csv(const std::string& path, const Contacts<Real>& c) {
  const std::string tmp = h5::temp_name(path);
  h5::check_output_directory(path);
  {
    std::FILE* f = std::fopen(tmp.c_str(), "w");
    if (!f) throw IoError(path + ": cannot write: " + std::strerror(errno));
    // every field the run produced (kContactFields order); a vector field is three columns
    std::string header;
    for_each_contact_field(c, c.full, [&](auto index, const auto&) {
      const ContactField& field = kContactFields[index];
      const std::string name = field.name();
      header += header.empty() ? "" : ",";
      header += field.kind == FieldKind::vector ? name + "_x," + name + "_y," + name + "_z" : name;
    });
    fmt::print(f, "{}\n", header);
    fmt::memory_buffer row;
    for (std::size_t k = 0; k < c.size(); ++k) {
      row.clear();
      for_each_contact_field(c, c.full, [&](auto, const auto& column) {
        if constexpr (requires { column[k].x; })
          fmt::format_to(std::back_inserter(row), "{},{},{},", column[k].x, column[k].y, column[k].z);
        else
          fmt::format_to(std::back_inserter(row), "{},", column[k]);
      });
      row[row.size() - 1] = '\n';
      std::fwrite(row.data(), 1, row.size(), f);
    }
    if (std::fclose(f) != 0) {
      std::filesystem::remove(tmp);
      throw IoError(path + ": write failed");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp);
    throw IoError(path + ": cannot rename temporary file: " + ec.message());
  }
}
template void write_contacts_csv(const std::string&, const Contacts<float>&);
template void write_contacts_csv(const std::string&, const Contacts<double>&);

}  // namespace cg
