// text_file.cpp: the atomic text write (see text_file.hpp).
#include "io/text_file.hpp"

#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "errors.hpp"

namespace cg {

void write_text_file(const std::string& path, const std::string& text) {
  namespace fs = std::filesystem;
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  std::error_code ec;
  {
    std::ofstream f(tmp, std::ios::binary);
    f << text;
    f.close();
    if (!f) {
      fs::remove(tmp, ec);
      throw IoError(path + ": cannot write");
    }
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw IoError(path + ": cannot rename the temporary file: " + ec.message());
  }
}

}  // namespace cg
