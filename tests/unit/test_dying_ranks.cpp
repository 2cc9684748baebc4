// A rank that dies during `mpirun -np 3 contactgrid detect`: killed (SIGKILL) or exiting (exit(1)) at
// each stage — read, exchange, detect, gather, write — the job must end non-zero within seconds, with
// a message naming that rank, and leave neither an output file nor a temporary. The test-only knob
// CONTACTGRID_TEST_FAULT (src/run/test_fault.hpp) makes the rank die exactly there. The launcher
// (Open MPI) ends the other ranks with SIGTERM, which ends them at once (src/run/stop.hpp), removing
// the temporaries they registered; a rank that calls exit() says so and removes its own.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <chrono>
#include <filesystem>
#include <string>

#include "support/child_process.hpp"
#include "support/paths.hpp"
#include "support/run_cli.hpp"
#include "temp_dir.hpp"

namespace cg::test {
namespace {

struct DyingRank {
  const char* action;  // kill | exit
  const char* stage;
  int rank;
  const char* write;  // --write
};

std::string case_name(const testing::TestParamInfo<DyingRank>& info) {
  return std::string(info.param.action) + "_" + info.param.stage + "_rank" + std::to_string(info.param.rank) +
         "_" + info.param.write;
}

class DyingRanks : public TempDirTest, public testing::WithParamInterface<DyingRank> {};

TEST_P(DyingRanks, EndTheJobWithinSecondsAndLeaveNoFile) {
  const DyingRank& c = GetParam();
  const CliResult g = run_cli("generate " + path("scene.h5") + " -n 20000 --seed 3 -q");
  ASSERT_EQ(g.code, 0) << g.output;
  const std::string fault = std::string(c.action) + "@" + c.stage + ":" + std::to_string(c.rank);
  // --read own: the bodies and ghosts move between ranks, so "exchange" is real communication
  ChildProcess job({cg::test::mpiexec(), "-np", "3", "--oversubscribe", "--allow-run-as-root",
                    cg::test::cli_binary(), "detect", path("scene.h5"), "-o", path("out.h5"), "--backend",
                    "cpu", "--threads", "1", "--read", "own", "--write", c.write, "-q"},
                   {"CONTACTGRID_TEST_FAULT=" + fault, "OMPI_ALLOW_RUN_AS_ROOT=1",
                    "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1", "OMPI_MCA_rmaps_base_oversubscribe=1"});
  const std::string said = "test fault: rank " + std::to_string(c.rank) + " " + c.action + " at " + c.stage;
  ASSERT_TRUE(job.wait_for_output(said, 300)) << job.output();
  const auto t0 = std::chrono::steady_clock::now();
  const auto status = job.wait(120);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(status.has_value()) << "the job did not end within 120 s of the fault:\n" << job.output();
  EXPECT_TRUE(!WIFEXITED(*status) || WEXITSTATUS(*status) != 0) << status_text(status) << "\n"
                                                                << job.output();
  EXPECT_LT(seconds, 30.0) << job.output();
  std::printf("[ fault %s ] the job ended %.2f s after the fault: %s\n", fault.c_str(), seconds,
              status_text(status).c_str());
  // The rank is named: by the launcher for a killed rank, by the rank itself when it exits.
  const std::string named = std::string(c.action) == "kill"
                                ? "process rank " + std::to_string(c.rank) + " "
                                : "[rank " + std::to_string(c.rank) + "/3] exited before the run finished";
  EXPECT_NE(job.output().find(named), std::string::npos) << "no '" << named << "' in:\n" << job.output();
  for (const auto& name : entries()) EXPECT_EQ(name, "scene.h5") << "left behind: " << name;
}

INSTANTIATE_TEST_SUITE_P(
    Stages, DyingRanks,
    testing::Values(DyingRank{"kill", "read", 2, "gather"}, DyingRank{"exit", "read", 1, "gather"},
                    DyingRank{"kill", "exchange", 1, "gather"}, DyingRank{"exit", "exchange", 2, "gather"},
                    DyingRank{"kill", "detect", 0, "gather"}, DyingRank{"exit", "detect", 1, "gather"},
                    DyingRank{"kill", "gather", 1, "gather"}, DyingRank{"exit", "gather", 0, "gather"},
                    DyingRank{"kill", "write", 1, "gather"}, DyingRank{"exit", "write", 2, "gather"},
                    DyingRank{"kill", "write", 0, "ranks"}, DyingRank{"kill", "gather", 2, "ranks"}),
    case_name);

}  // namespace
}  // namespace cg::test
