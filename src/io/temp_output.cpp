// temp_output.cpp: the temporary of an output (see temp_output.hpp).
#include "io/temp_output.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "errors.hpp"

namespace cg {

std::string temp_name(const std::string& path) { return path + ".tmp." + std::to_string(::getpid()); }

void remove_quietly(const std::string& file) noexcept {
  std::error_code ec;
  std::filesystem::remove(file, ec);
}

void check_output_directory(const std::string& path) {
  namespace fs = std::filesystem;
  const fs::path parent = fs::path(path).parent_path();
  const std::string dir = parent.empty() ? std::string(".") : parent.string();
  std::error_code ec;
  const fs::file_status st = fs::status(dir, ec);
  auto fail = [&](const std::string& why) {
    throw IoError(fmt::format("{}: cannot write into the directory {}: {}", path, dir, why));
  };
  if (st.type() == fs::file_type::none) fail(ec.message());  // e.g. a parent not searchable
  if (!fs::exists(st)) fail("it does not exist");
  if (!fs::is_directory(st)) fail("it is not a directory");
  if (::access(dir.c_str(), W_OK | X_OK) != 0) fail(std::strerror(errno));
}

TempOutput::TempOutput(std::string path)
    : m_path(std::move(path)), m_temp(temp_name(m_path)), m_cleanup(CleanupAction::remove_file(m_temp)) {
  check_output_directory(m_path);
}

TempOutput::~TempOutput() {
  if (!m_done) remove_quietly(m_temp);
}

void TempOutput::commit() {
  stop_point();
  if (std::rename(m_temp.c_str(), m_path.c_str()) != 0) {
    int error = errno;
    throw IoError(fmt::format("{}: cannot rename {} over it: {}", m_path, m_temp, std::strerror(error)));
  }
  m_done = true;
  m_cleanup.release();
}

}  // namespace cg
