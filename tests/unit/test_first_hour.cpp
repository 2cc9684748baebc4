// The first hour of a new user at the command line (issue #36): what a one-rank run prints, how enum
// options and bad counts are named, and where an unwritable output is reported.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "support/run_cli.hpp"
#include "temp_dir.hpp"

namespace cg::test {
namespace {

class FirstHour : public TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    const CliResult g = run_cli("generate " + path("s.h5") + " -n 3000 --seed 3 -q");
    ASSERT_EQ(g.code, 0) << g.output;
  }
};

// One rank sends nothing: no merge line, no rows for redistribute, halo, gather or merge, and no
// "maximum over ranks".
TEST_F(FirstHour, OneRankPrintsNoMpiLines) {
  const CliResult d = run_cli("detect " + path("s.h5") + " -o " + path("c.h5") + " --backend cpu -v");
  ASSERT_EQ(d.code, 0) << d.output;
  EXPECT_NE(d.output.find("1 rank(s)"), std::string::npos) << d.output;
  EXPECT_NE(d.output.find("  detect "), std::string::npos) << d.output;
  EXPECT_NE(d.output.find("  write "), std::string::npos) << d.output;
  for (const char* mpi_only : {"merge", "redistribute", "halo", "gather", "maximum over ranks", "ghosts"})
    EXPECT_EQ(d.output.find(mpi_only), std::string::npos) << "'" << mpi_only << "' in:\n" << d.output;
}

// Enum options show and accept their names; the enum's internal numbers appear nowhere.
TEST_F(FirstHour, EnumOptionsListTheirNames) {
  const CliResult help = run_cli("detect --help");
  EXPECT_EQ(help.code, 0) << help.output;
  EXPECT_NE(help.output.find("auto|cpu|cuda"), std::string::npos) << help.output;
  EXPECT_NE(help.output.find("basic|full"), std::string::npos) << help.output;
  EXPECT_NE(help.output.find("auto|x|y|z"), std::string::npos) << help.output;
  EXPECT_EQ(help.output.find("->"), std::string::npos) << help.output;
  for (const char* command : {"bench", "bench-broad", "simulate", "generate", "validate", "study"}) {
    const CliResult other = run_cli(std::string(command) + " --help");
    EXPECT_EQ(other.code, 0) << command << ": " << other.output;
    EXPECT_EQ(other.output.find("->"), std::string::npos) << command << ": " << other.output;
  }

  const CliResult bad = run_cli("detect " + path("s.h5") + " -o " + path("c.h5") + " --backend gpu");
  EXPECT_EQ(bad.code, 2) << bad.output;
  EXPECT_NE(bad.output.find("--backend: 'gpu' is not one of auto|cpu|cuda"), std::string::npos) << bad.output;
  EXPECT_EQ(bad.output.find("->"), std::string::npos) << bad.output;
  const CliResult axis = run_cli("detect " + path("s.h5") + " -o " + path("c.h5") + " --axis w");
  EXPECT_EQ(axis.code, 2) << axis.output;
  EXPECT_NE(axis.output.find("'w' is not one of auto|x|y|z"), std::string::npos) << axis.output;

  const CliResult named = run_cli("detect " + path("s.h5") + " -o " + path("c.h5") +
                                  " --backend cpu --fields full --axis z --balance width -q");
  EXPECT_EQ(named.code, 0) << named.output;
}

// `generate -n 0` names -n, the option typed.
TEST_F(FirstHour, CountZeroIsReportedAsDashN) {
  for (const char* n : {"0", "-3", "300000000"}) {
    const CliResult r = run_cli("generate " + path("g.h5") + " -n " + n);
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_NE(r.output.find(std::string("-n (--count) ") + n + ": the number of bodies must be 1"),
              std::string::npos)
        << r.output;
    EXPECT_FALSE(std::filesystem::exists(path("g.h5")));
  }
}

// An output directory that does not exist: detect (exit 6, I/O, before it reads the scene) and
// generate name it, without the temporary name or HDF5's flags; so does the CSV copy.
TEST_F(FirstHour, UnwritableOutputNamesTheDirectory) {
  const std::string dir = path("missing");
  const CliResult d = run_cli("detect " + path("s.h5") + " -o " + dir + "/c.h5 --backend cpu");
  EXPECT_EQ(d.code, 6) << d.output;
  EXPECT_NE(d.output.find("cannot write into the directory " + dir + ": it does not exist"),
            std::string::npos)
      << d.output;
  const CliResult g = run_cli("generate " + dir + "/s.h5 -n 10 -q");
  EXPECT_EQ(g.code, 6) << g.output;
  EXPECT_NE(g.output.find(dir + "/s.h5: cannot write into the directory " + dir + ": it does not exist"),
            std::string::npos)
      << g.output;
  for (const std::string& out : {d.output, g.output}) {
    EXPECT_EQ(out.find(".tmp."), std::string::npos) << out;
    EXPECT_EQ(out.find("flags"), std::string::npos) << out;
  }
  const CliResult csv =
      run_cli("detect " + path("s.h5") + " -o " + path("c.h5") + " --backend cpu --csv " + dir + "/c.csv");
  EXPECT_EQ(csv.code, 6) << csv.output;
  EXPECT_NE(csv.output.find("cannot write into the directory " + dir + ": it does not exist"),
            std::string::npos)
      << csv.output;
}

}  // namespace
}  // namespace cg::test
