// Disk and memory: a write that runs out of room — a full filesystem (a tiny tmpfs in a private mount
// namespace: ENOSPC) or the file size limit (ulimit -f: SIGXFSZ, then EFBIG) — ends `detect` (or `simulate`)
// with its documented exit code and leaves nothing: neither the contact file nor its CSV copy nor a
// temporary, whichever write it was. A host allocation that fails (ulimit -v) is "out of host memory", exit
// 7, not a crash. docs/ERRORS.md lists the codes.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "io/temp_output.hpp"
#include "support/paths.hpp"
#include "support/run_cli.hpp"
#include "support/shell.hpp"
#include "temp_dir.hpp"

namespace fs = std::filesystem;

namespace cg::test {
namespace {

class FullDisk : public TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    // 20000 bodies: about 8000 contacts, a contact file of ~0.8 MB and a CSV copy of ~1.6 MB
    const CliResult g = run_cli("generate " + path("scene.h5") + " -n 20000 --seed 4 -q");
    ASSERT_EQ(g.code, 0) << g.output;
    fs::create_directories(path("disk"));
  }
  std::string detect_into(const std::string& dir) const {
    return cg::test::cli_binary() + " detect " + path("scene.h5") + " -o " + dir + "/out.h5 --csv " + dir +
           "/out.csv --backend cpu --threads 2 -q";
  }
};

// The filesystem fills up while the file is created (16 KiB), while its rows are written (256 KiB)
// and while the CSV copy is written after the contact file was complete (1200 KiB): exit 6 each time,
// the message names the file and the reason, and nothing is left on the filesystem.
TEST_F(FullDisk, NoSpaceLeftEndsWithExit6AndLeavesNothing) {
  for (int kib : {16, 256, 1200}) {
    SCOPED_TRACE(std::to_string(kib) + " KiB");
    const ShellResult r = run_on_small_tmpfs(path("disk"), kib, detect_into(path("disk")));
    if (r.code == -1 && r.output.empty()) GTEST_SKIP() << "no tmpfs in a user namespace here (unshare -rm)";
    EXPECT_EQ(r.code, 6) << r.output;
    EXPECT_NE(r.output.find("No space left on device"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("LEFT:\n"), std::string::npos) << "files left on the full filesystem:\n"
                                                           << r.output;
  }
  // and with room enough, the same command writes both
  const ShellResult ok = run_on_small_tmpfs(path("disk"), 8192, detect_into(path("disk")));
  EXPECT_EQ(ok.code, 0) << ok.output;
  EXPECT_NE(ok.output.find("LEFT:out.csv out.h5"), std::string::npos) << ok.output;
}

// --xdmf: the XDMF sidecar (<out>.xdmf.h5) and XMF files are written after the contact file and its CSV
// copy. A filesystem with room for those two but not for the XDMF files ends with exit 6 and removes
// all of them; with room, all appear. generate --xdmf likewise: the scene goes with its XDMF files.
// Sizes of this scene's files: contacts 748 KiB, CSV 1540 KiB, XDMF sidecar 116 KiB; the scene
// 636 KiB and its sidecar 84 KiB. So 2340 KiB hold the contacts and the CSV copy but not the
// sidecar, 680 KiB the scene but not its sidecar.
TEST_F(FullDisk, XdmfFilesAppearWithTheOutputsOrNothingDoes) {
  constexpr int kXdmfDoesNotFitKiB = 2340, kSceneOnlyKiB = 680;
  const std::string detect = detect_into(path("disk")) + " --xdmf";
  const ShellResult roomy =
      run_on_small_tmpfs(path("disk"), 8192, detect + " && du -k " + path("disk") + "/*");
  if (roomy.code == -1 && roomy.output.empty())
    GTEST_SKIP() << "no tmpfs in a user namespace here (unshare -rm)";
  ASSERT_EQ(roomy.code, 0) << roomy.output;
  EXPECT_NE(roomy.output.find("LEFT:out.csv out.h5 out.spheres.xmf out.xdmf.h5 out.xmf"), std::string::npos)
      << roomy.output;
  for (int kib : {kXdmfDoesNotFitKiB}) {
    SCOPED_TRACE(std::to_string(kib) + " KiB");
    const ShellResult r = run_on_small_tmpfs(path("disk"), kib, detect);
    EXPECT_EQ(r.code, 6) << r.output;
    EXPECT_NE(r.output.find("No space left on device"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("out.xdmf.h5"), std::string::npos)
        << "not the XDMF write that failed: " << r.output;
    EXPECT_NE(r.output.find("LEFT:\n"), std::string::npos) << "files left on the full filesystem:\n"
                                                           << r.output;
  }
  const std::string generate =
      cg::test::cli_binary() + " generate " + path("disk") + "/s.h5 -n 20000 --seed 4 -q --xdmf";
  for (int kib : {16, kSceneOnlyKiB}) {
    SCOPED_TRACE("generate, " + std::to_string(kib) + " KiB");
    const ShellResult r = run_on_small_tmpfs(path("disk"), kib, generate);
    EXPECT_EQ(r.code, 6) << r.output;
    EXPECT_NE(r.output.find("No space left on device"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("LEFT:\n"), std::string::npos) << "files left on the full filesystem:\n"
                                                           << r.output;
  }
  const ShellResult scene = run_on_small_tmpfs(path("disk"), 8192, generate);
  EXPECT_EQ(scene.code, 0) << scene.output;
  EXPECT_NE(scene.output.find("LEFT:s.h5 s.spheres.xmf s.xdmf.h5\n"), std::string::npos) << scene.output;
}

// simulate on a filesystem that fills up after a few frames (each frame of this pour ~34 KiB, the
// whole run ~800 KiB): exit 6 naming the disk's reason, no temporary frame left, every frame that is
// there reads back as a scene, and neither log.csv nor run.xdmf says the run completed.
TEST_F(FullDisk, SimulateStopsWithExit6AndItsRunSaysItDidNotFinish) {
  const CliResult g =
      run_cli("generate " + path("pour.h5") + " --kind pour -n 300 --rlow 0.004 --rhigh 0.005 --seed 3 -q");
  ASSERT_EQ(g.code, 0) << g.output;
  const std::string run_dir = path("disk") + "/run";
  const std::string script =
      cg::test::cli_binary() + " simulate " + path("pour.h5") + " -o " + run_dir +
      " --steps 400 --output-every 20 --backend cpu --threads 2 --no-plot -q; echo RC:$?; "
      "echo LOG:$(tail -n 1 " +
      run_dir +
      "/log.csv); "
      "grep -o \"Name=.status. Value=.[a-z]*.\" " +
      run_dir +
      "/run.xdmf; "
      "for f in " +
      run_dir + "/frame_*.h5; do " + cg::test::cli_binary() + " detect $f -o " + path("check.h5") +
      " --backend cpu -q >/dev/null 2>&1 && echo FRAME_OK || echo FRAME_BAD:$f; done; "
      "echo RUN:$(ls -A " +
      run_dir + ")";
  const ShellResult r = run_on_small_tmpfs(path("disk"), 256, script);
  if (r.code == -1 && r.output.empty()) GTEST_SKIP() << "no tmpfs in a user namespace here (unshare -rm)";
  EXPECT_NE(r.output.find("RC:6\n"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("No space left on device"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("LOG:# status: complete"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("Value=\"running\""), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("FRAME_OK"), std::string::npos) << "no frame was written before the disk filled:\n"
                                                          << r.output;
  EXPECT_EQ(r.output.find("FRAME_BAD"), std::string::npos) << r.output;
  const std::size_t listing = r.output.find("RUN:");
  ASSERT_NE(listing, std::string::npos) << r.output;
  const std::string run_files = r.output.substr(listing, r.output.find('\n', listing) - listing);
  EXPECT_EQ(run_files.find(".tmp."), std::string::npos) << "a temporary frame was left: " << run_files;
  EXPECT_NE(run_files.find("log.csv"), std::string::npos) << run_files;
}

// The file size limit: below the contact file's size, and above it but below the CSV's. The kernel's
// SIGXFSZ stops the run (exit status 153 = 128 + SIGXFSZ), the failed write says why, nothing is left.
TEST_F(FullDisk, FileSizeLimitEndsWithStatus153AndLeavesNothing) {
  for (int kib : {100, 1200}) {  // bash's ulimit -f counts KiB (dash's, 512-byte blocks)
    SCOPED_TRACE(std::to_string(kib) + " KiB");
    const ShellResult r =
        run_shell("ulimit -f " + std::to_string(kib) + " && " + detect_into(path(".")) + "; echo status:$?",
                  "/bin/bash");
    EXPECT_NE(r.output.find("status:153"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("stopped by SIGXFSZ"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("File too large"), std::string::npos) << r.output;
    for (const auto& name : entries())
      EXPECT_TRUE(name == "scene.h5" || name == "disk") << "left behind: " << name;
  }
}

// A scene whose bodies pile into one cell asks for the memory of ~2·10^9 candidate pairs: under a
// 2 GiB address-space limit the allocation fails inside the pair stage's worker threads, which is
// reported as out of host memory (exit 7), with no output.
TEST_F(FullDisk, HostAllocationFailureIsOutOfHostMemory) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "AddressSanitizer reserves terabytes of address space: no ulimit -v under it";
#endif
  const CliResult g = run_cli("generate " + path("pile.h5") +
                              " -n 60000 --seed 2 --rlow 0.001 --rhigh 0.001 "
                              "--contacts-per-body 100000 -q");
  ASSERT_EQ(g.code, 0) << g.output;
  const ShellResult r =
      run_shell("ulimit -v 2000000 && " + cg::test::cli_binary() + " detect " + path("pile.h5") + " -o " +
                path("out.h5") + " --backend cpu --threads 2 --precision fp64");
  EXPECT_EQ(r.code, 7) << r.output;
  EXPECT_NE(r.output.find("out of host memory"), std::string::npos) << r.output;
  for (const auto& name : entries())
    EXPECT_TRUE(name == "scene.h5" || name == "pile.h5" || name == "disk") << "left behind: " << name;
}

// The outputs of one command appear all or none: FinishedOutputs removes the files it was given unless
// kept, and registers them for removal should a signal end the process at once.
TEST_F(FullDisk, FinishedOutputsAreRemovedUnlessKept) {
  for (const char* name : {"a", "b", "c"}) std::ofstream(path(name)) << name;
  const std::size_t before = cleanup_actions_registered();
  {
    FinishedOutputs outputs;
    outputs.add(path("a"));
    outputs.add(path("b"));
    EXPECT_EQ(cleanup_actions_registered(), before + 2);
  }
  EXPECT_FALSE(fs::exists(path("a")));
  EXPECT_FALSE(fs::exists(path("b")));
  {
    FinishedOutputs outputs;
    outputs.add(path("c"));
    outputs.keep();
  }
  EXPECT_TRUE(fs::exists(path("c")));
  EXPECT_EQ(cleanup_actions_registered(), before);
}

}  // namespace
}  // namespace cg::test
