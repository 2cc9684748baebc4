#pragma once
// Where the tests find the contactgrid binary, the source tree and mpiexec: the build's paths
// (CG_BINARY, CG_SOURCE_DIR, CG_MPIEXEC, set by tests/CMakeLists.txt), unless the environment variable
// of the same name says otherwise — a copy of the test binary run on another machine (the GPU host of
// jobs/gpu_wave5_check.sh) points them at its own copies.
#include <cstdlib>
#include <string>

namespace cg::test {

inline std::string path_setting(const char* variable, const char* built_in) {
  const char* v = std::getenv(variable);
  return v && *v ? std::string(v) : std::string(built_in);
}

inline std::string cli_binary() { return path_setting("CG_BINARY", CG_BINARY); }
inline std::string source_dir() { return path_setting("CG_SOURCE_DIR", CG_SOURCE_DIR); }
inline std::string mpiexec() { return path_setting("CG_MPIEXEC", CG_MPIEXEC); }

}  // namespace cg::test
