// text_file.cpp: the atomic text write (see text_file.hpp).
#include "io/text_file.hpp"

#include <cerrno>
#include <cstdio>
#include <cstring>

#include "errors.hpp"
#include "io/temp_output.hpp"

namespace cg {

void write_text_file(const std::string& path, const std::string& text) {
  TempOutput out(path);
  std::FILE* f = std::fopen(out.temp().c_str(), "wb");
  if (!f) throw IoError(path + ": cannot open " + out.temp() + " for writing: " + std::strerror(errno));
  const std::size_t written = std::fwrite(text.data(), 1, text.size(), f);
  const int write_error = errno;
  if (std::fclose(f) != 0 || written != text.size())
    throw IoError(path + ": cannot write: " + std::strerror(written != text.size() ? write_error : errno));
  out.commit();
}

}  // namespace cg
