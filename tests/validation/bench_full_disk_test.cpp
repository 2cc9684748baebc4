// `contactgrid bench` on a filesystem too small for its plots (a tmpfs of 16 KiB in a private mount
// namespace): the CSV, its result, is written; the plots, which are optional, appear all four or none
// (gnuplot exits 0 with truncated files on a full disk; bench checks each file's end), and no
// temporary is left. With room, all four appear.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "support/shell.hpp"
#include "temp_dir.hpp"

namespace cg::test {
namespace {

class BenchFullDisk : public TempDirTest {};

TEST_F(BenchFullDisk, PlotsAppearAllOrNone) {
  std::filesystem::create_directories(path("disk"));
  const std::string bench = std::string(CG_BINARY) +
                            " bench --lo 8 --bullet-hi 9 --engine-hi 9 --repetitions 1 " +
                            "--backend cpu --csv " + path("disk") + "/b.csv";
  const ShellResult full = run_on_small_tmpfs(path("disk"), 16, bench);
  if (full.code == -1 && full.output.empty())
    GTEST_SKIP() << "no tmpfs in a user namespace here (unshare -rm)";
  if (full.output.find("gnuplot is not on PATH") != std::string::npos) GTEST_SKIP() << "no gnuplot";
  EXPECT_EQ(full.code, 0) << full.output;
  EXPECT_NE(full.output.find("plot: gnuplot did not write all of"), std::string::npos) << full.output;
  EXPECT_NE(full.output.find("LEFT:b.csv\n"), std::string::npos) << full.output;

  const ShellResult roomy = run_on_small_tmpfs(path("disk"), 4096, bench);
  EXPECT_EQ(roomy.code, 0) << roomy.output;
  EXPECT_NE(roomy.output.find("LEFT:b.csv b_loglog.png b_loglog.svg b_time.png b_time.svg\n"),
            std::string::npos)
      << roomy.output;
}

}  // namespace
}  // namespace cg::test
