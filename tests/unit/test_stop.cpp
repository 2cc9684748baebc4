// Stopping a run: the signals that end `detect` (src/run/stop.hpp) and the cleanup actions behind them.
// A child `contactgrid detect` is held at a known point by the test-only knob CONTACTGRID_TEST_FAULT
// (src/run/test_fault.hpp) — "wait" stops at a signal like any stage, "hang" never looks — and then
// signalled; it must end as documented (docs/ERRORS.md), say why, and leave neither its output nor
// its temporary.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

#include "errors.hpp"
#include "run/stop.hpp"
#include "support/child_process.hpp"
#include "support/paths.hpp"
#include "support/run_cli.hpp"
#include "temp_dir.hpp"

namespace fs = std::filesystem;

namespace cg::test {
namespace {

class Stop : public TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    const CliResult g = run_cli("generate " + path("scene.h5") + " -n 2000 --seed 5 -q");
    ASSERT_EQ(g.code, 0) << g.output;
  }

  // detect of the scene into out.h5 (and out.csv), held by `fault`; the stop grace `grace` seconds.
  std::unique_ptr<ChildProcess> start_detect(const std::string& fault, int grace) {
    return std::make_unique<ChildProcess>(
        std::vector<std::string>{cg::test::cli_binary(), "detect", path("scene.h5"), "-o", path("out.h5"),
                                 "--csv", path("out.csv"), "--backend", "cpu", "--threads", "1"},
        std::vector<std::string>{"CONTACTGRID_TEST_FAULT=" + fault,
                                 "CONTACTGRID_STOP_GRACE=" + std::to_string(grace), "CONTACTGRID_MPI=0"});
  }

  // Nothing in the directory but the scene: no output, no CSV, no temporary.
  void expect_only_the_scene() const {
    for (const auto& name : entries()) EXPECT_EQ(name, "scene.h5") << "left behind: " << name;
  }

  static bool ended_by(const std::optional<int>& status, int signal) {
    if (!status) return false;
    if (signal == SIGXFSZ) return WIFEXITED(*status) && WEXITSTATUS(*status) == 128 + SIGXFSZ;
    return WIFSIGNALED(*status) && WTERMSIG(*status) == signal;
  }
};

// Each stop signal, while the output's temporary exists: the run stops at its next stop point, the
// temporary goes, and the process ends as the signal does (exit status 153 for SIGXFSZ).
TEST_F(Stop, EverySignalDuringTheWriteLeavesNoFile) {
  for (int signal : {SIGINT, SIGTERM, SIGPIPE, SIGXFSZ}) {
    SCOPED_TRACE(signal_name(signal));
    auto child = start_detect("wait@write", 60);
    ASSERT_TRUE(child->wait_for_output("test fault: rank 0 wait at write", 60)) << child->output();
    const std::string temp = path("out.h5") + ".tmp." + std::to_string(child->pid());
    EXPECT_TRUE(fs::exists(temp)) << "the run should be writing " << temp;
    child->signal(signal);
    const auto status = child->wait(30);
    EXPECT_TRUE(ended_by(status, signal)) << status_text(status) << "\n" << child->output();
    EXPECT_NE(child->output().find(std::string("stopped by ") + signal_name(signal)), std::string::npos)
        << child->output();
    expect_only_the_scene();
  }
}

// A stop before anything is written (the engine's stage) leaves nothing either.
TEST_F(Stop, SigtermBeforeTheWriteLeavesNoFile) {
  auto child = start_detect("wait@detect", 60);
  ASSERT_TRUE(child->wait_for_output("test fault: rank 0 wait at detect", 60)) << child->output();
  child->signal(SIGTERM);
  const auto status = child->wait(30);
  EXPECT_TRUE(ended_by(status, SIGTERM)) << status_text(status) << "\n" << child->output();
  expect_only_the_scene();
}

// A stage that never reaches a stop point: the first SIGINT only asks (the run goes on), the second
// ends it at once, the cleanup actions removing the temporary from the signal handler.
TEST_F(Stop, ASecondSigintEndsAtOnce) {
  auto child = start_detect("hang@write", 600);
  ASSERT_TRUE(child->wait_for_output("test fault: rank 0 hang at write", 60)) << child->output();
  const std::string temp = path("out.h5") + ".tmp." + std::to_string(child->pid());
  ASSERT_TRUE(fs::exists(temp));
  child->signal(SIGINT);
  ASSERT_TRUE(child->wait_for_output("a second SIGINT stops at once", 10)) << child->output();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_TRUE(child->running()) << "the first SIGINT should only ask the run to stop";
  const auto t0 = std::chrono::steady_clock::now();
  child->signal(SIGINT);
  const auto status = child->wait(30);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_TRUE(ended_by(status, SIGINT)) << status_text(status) << "\n" << child->output();
  EXPECT_LT(seconds, 5.0) << "the second SIGINT should end the run at once";
  EXPECT_NE(child->output().find("temporary files removed"), std::string::npos) << child->output();
  expect_only_the_scene();
}

// The same stage and one signal: CONTACTGRID_STOP_GRACE seconds later the run ends at once anyway.
TEST_F(Stop, TheGraceEndsARunThatNeverStops) {
  auto child = start_detect("hang@write", 1);
  ASSERT_TRUE(child->wait_for_output("test fault: rank 0 hang at write", 60)) << child->output();
  const auto t0 = std::chrono::steady_clock::now();
  child->signal(SIGTERM);
  const auto status = child->wait(30);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_TRUE(ended_by(status, SIGTERM)) << status_text(status) << "\n" << child->output();
  EXPECT_GE(seconds, 0.9);
  EXPECT_LT(seconds, 10.0);
  expect_only_the_scene();
}

// A malformed knob is a usage error, before anything runs.
TEST_F(Stop, MalformedKnobsAreUsageErrors) {
  for (const std::string env : {"CONTACTGRID_TEST_FAULT=sleep@write", "CONTACTGRID_TEST_FAULT=wait@nowhere",
                                "CONTACTGRID_STOP_GRACE=soon", "CONTACTGRID_STOP_GRACE=-1"}) {
    ChildProcess child(
        {cg::test::cli_binary(), "detect", path("scene.h5"), "-o", path("out.h5"), "--backend", "cpu"},
        {env, "CONTACTGRID_MPI=0"});
    const auto status = child.wait(60);
    ASSERT_TRUE(status && WIFEXITED(*status)) << env << ": " << status_text(status);
    EXPECT_EQ(WEXITSTATUS(*status), 2) << env << "\n" << child.output();
    expect_only_the_scene();
  }
}

// The registry itself: actions run once, in place, when run_cleanup_actions is called; released ones
// never run; the keyed form registers and forgets by path.
TEST_F(Stop, CleanupActionsRunOnceAndOnlyWhileRegistered) {
  auto write = [](const std::string& p, const std::string& text) { std::ofstream(p) << text; };
  auto read = [](const std::string& p) {
    std::ifstream f(p);
    std::stringstream s;
    s << f.rdbuf();
    return s.str();
  };
  const std::size_t before = cleanup_actions_registered();
  write(path("a.tmp"), "a");
  write(path("b.tmp"), "b");
  write(path("kept"), "kept");
  write(path("keyed.tmp"), "k");
  write(path("log.csv"), "step\n");
  {
    CleanupAction a = CleanupAction::remove_file(path("a.tmp"));
    CleanupAction b = CleanupAction::remove_file(path("b.tmp"));
    CleanupAction marker = CleanupAction::write_file(path("INCOMPLETE"), "stopped\n");
    CleanupAction log = CleanupAction::append_file(path("log.csv"), "incomplete\n");
    CleanupAction moved = std::move(b);
    EXPECT_FALSE(b.active());
    CleanupAction kept = CleanupAction::remove_file(path("kept"));
    kept.release();
    remove_on_stop(path("keyed.tmp"));
    remove_on_stop(path("kept"));
    forget_on_stop(path("kept"));
    EXPECT_EQ(cleanup_actions_registered(), before + 5);
    run_cleanup_actions();
    EXPECT_EQ(cleanup_actions_registered(), before);
    run_cleanup_actions();  // each action runs once
  }
  EXPECT_FALSE(fs::exists(path("a.tmp")));
  EXPECT_FALSE(fs::exists(path("b.tmp")));
  EXPECT_FALSE(fs::exists(path("keyed.tmp")));
  EXPECT_TRUE(fs::exists(path("kept")));
  EXPECT_EQ(read(path("INCOMPLETE")), "stopped\n");
  EXPECT_EQ(read(path("log.csv")), "step\nincomplete\n");
  EXPECT_EQ(cleanup_actions_registered(), before);
  EXPECT_THROW(CleanupAction::remove_file(std::string(kCleanupPathBytes, 'x')), Error);
}

}  // namespace
}  // namespace cg::test
