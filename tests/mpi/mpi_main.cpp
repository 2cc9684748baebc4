// Test main of contactgrid_mpi_tests, run by CTest under mpiexec at 1, 2, 3 and 4 ranks (and runnable
// alone: laptop mode, one rank without MPI). Every rank runs every test (the tests are collective);
// the result is reduced so every rank returns the same exit code. Only rank 0 prints the usual
// GoogleTest output; other ranks print their failures, prefixed "[rank r/N]".
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <iostream>

#include "io/scene_file.hpp"
#include "mpi/mpi_test_env.hpp"

namespace cg::testing {
namespace {

Session* g_session = nullptr;
std::string g_temp_dir;

// Failures of a rank other than 0, one line each.
class RankFailurePrinter : public ::testing::EmptyTestEventListener {
 public:
  explicit RankFailurePrinter(std::string prefix) : m_prefix(std::move(prefix)) {}
  void OnTestPartResult(const ::testing::TestPartResult& r) override {
    if (!r.failed()) return;
    std::fprintf(stderr, "%s%s:%d: %s\n", m_prefix.c_str(), r.file_name() ? r.file_name() : "?",
                 r.line_number(), r.summary());
  }

 private:
  std::string m_prefix;
};

}  // namespace

Session& session() { return *g_session; }
const std::string& shared_temp_dir() { return g_temp_dir; }

std::string shared_path(const std::string& name) { return g_temp_dir + "/" + name; }

std::string write_shared(const std::string& name, const Scene& scene) {
  const std::string path = shared_path(name + ".h5");
  std::exception_ptr error;
  if (session().rank() == 0) {
    try {
      write_scene(path, scene);
    } catch (...) {
      error = std::current_exception();
    }
  }
  session().agree(error, "write_scene");
  return path;
}

}  // namespace cg::testing

int main(int argc, char** argv) {
  try {
    cg::Session session(&argc, &argv);
    cg::testing::g_session = &session;
    ::testing::InitGoogleTest(&argc, argv);
    if (session.rank() != 0) {
      auto& listeners = ::testing::UnitTest::GetInstance()->listeners();
      delete listeners.Release(listeners.default_result_printer());
      listeners.Append(new cg::testing::RankFailurePrinter(session.prefix()));
    }
    std::string dir;
    if (session.rank() == 0) {
      std::string pattern = (std::filesystem::temp_directory_path() / "contactgrid_mpi_XXXXXX").string();
      if (mkdtemp(pattern.data()) == nullptr) session.abort(6, "cannot create a temporary directory");
      dir = pattern;
    }
    cg::testing::g_temp_dir = session.broadcast(dir);

    const int rc = RUN_ALL_TESTS();
    const bool ok = session.all(rc == 0);
    session.barrier();
    if (session.rank() == 0) {
      std::error_code ec;
      std::filesystem::remove_all(cg::testing::g_temp_dir, ec);
      std::printf("contactgrid_mpi_tests: %d rank(s)%s: %s\n", session.size(),
                  session.uses_mpi() ? "" : " (laptop mode, no MPI)", ok ? "PASSED on every rank" : "FAILED");
    }
    return ok ? 0 : 1;
  } catch (const cg::Error& e) {
    std::fprintf(stderr, "contactgrid_mpi_tests: %s\n", e.what());
    return e.exit_code();
  }
}
