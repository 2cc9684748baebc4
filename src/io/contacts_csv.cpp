// contacts_csv.cpp: the CSV copy of the contacts (see contacts_csv.hpp).
#include "io/contacts_csv.hpp"

#include <fmt/format.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <iterator>
#include <memory>

#include "errors.hpp"
#include "io/temp_output.hpp"

namespace cg {

template <class Real>
void write_contacts_csv(const std::string& path, const Contacts<Real>& c) {
  TempOutput out(path);
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(out.temp().c_str(), "w"), std::fclose);
  if (!file) throw IoError(path + ": cannot write: " + std::strerror(errno));
  std::FILE* f = file.get();
  // every field the run produced (kContactFields order); a vector field is three columns
  std::string header;
  for_each_contact_field(c, c.full, [&](auto index, const auto&) {
    const ContactField& field = kContactFields[index];
    const std::string name = field.name();
    header += header.empty() ? "" : ",";
    header += field.kind == FieldKind::vector ? name + "_x," + name + "_y," + name + "_z" : name;
  });
  header += '\n';
  std::fwrite(header.data(), 1, header.size(), f);
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
    if (std::fwrite(row.data(), 1, row.size(), f) != row.size()) break;  // ferror below says why
    if (k % (1u << 20) == 0) stop_point();
  }
  const int write_error = std::ferror(f) ? errno : 0;
  const int closed = std::fclose(file.release());
  const int close_error = errno;
  if (write_error != 0 || closed != 0)
    throw IoError(path + ": cannot write " + out.temp() + ": " +
                  std::strerror(write_error != 0 ? write_error : close_error));
  out.commit();
}
template void write_contacts_csv(const std::string&, const Contacts<float>&);
template void write_contacts_csv(const std::string&, const Contacts<double>&);

}  // namespace cg
