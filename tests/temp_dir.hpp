#pragma once
// A fresh temporary directory per test case (named after the suite, the process and the test, so
// parallel CTest runs never share one), removed afterwards. path("x.h5") is a file inside it.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>
#include <vector>

namespace cg::test {

class TempDirTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    m_dir = std::filesystem::temp_directory_path() / (std::string("cg_") + info->test_suite_name() + "_" +
                                                      std::to_string(::getpid()) + "_" + info->name());
    std::filesystem::remove_all(m_dir);
    std::filesystem::create_directories(m_dir);
  }
  void TearDown() override {
    std::error_code ec;
    std::filesystem::remove_all(m_dir, ec);
  }
  std::string path(const std::string& name) const { return (m_dir / name).string(); }
  // Names of the files in the directory (to check that nothing, not even a temporary, was left).
  std::vector<std::string> entries() const {
    std::vector<std::string> names;
    for (const auto& e : std::filesystem::directory_iterator(m_dir))
      names.push_back(e.path().filename().string());
    return names;
  }

  std::filesystem::path m_dir;
};

}  // namespace cg::test
