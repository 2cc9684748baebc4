// `contactgrid validate SCENE CONTACTS` with a contact file of another scene (issue #36): refused with
// one line that says so (exit 3), before any comparison; the scene moved or copied under its own name
// is still its scene.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "support/run_cli.hpp"
#include "temp_dir.hpp"

namespace cg {
namespace {

namespace fs = std::filesystem;

class ValidateFiles : public test::TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    for (const auto& [name, args] :
         {std::pair{"a.h5", "-n 3000 --seed 5"}, std::pair{"b.h5", "-n 2000 --seed 5"},
          std::pair{"c.h5", "-n 3000 --seed 6"}}) {
      const test::CliResult g = test::run_cli("generate " + path(name) + " " + args + " -q");
      ASSERT_EQ(g.code, 0) << g.output;
    }
    const test::CliResult d =
        test::run_cli("detect " + path("a.h5") + " -o " + path("ca.h5") + " --backend cpu -q");
    ASSERT_EQ(d.code, 0) << d.output;
  }
  static std::size_t lines(const std::string& s) {
    std::size_t n = 0;
    for (char c : s) n += c == '\n';
    return n;
  }
};

TEST_F(ValidateFiles, ContactsOfAnotherSceneAreRefused) {
  const test::CliResult ok = test::run_cli("validate " + path("a.h5") + " " + path("ca.h5"));
  EXPECT_EQ(ok.code, 0) << ok.output;

  const test::CliResult count = test::run_cli("validate " + path("b.h5") + " " + path("ca.h5"));
  EXPECT_EQ(count.code, 3) << count.output;
  EXPECT_NE(
      count.output.find(path("ca.h5") + ": these contacts are of a scene of 3000 bodies (computed from " +
                        path("a.h5") + "), but " + path("b.h5") + " has 2000: not its contact file"),
      std::string::npos)
      << count.output;
  EXPECT_EQ(lines(count.output), 1u) << count.output;
  EXPECT_EQ(count.output.find("checked"), std::string::npos) << count.output;

  // Same body count, another file: the recorded input says so.
  const test::CliResult input = test::run_cli("validate " + path("c.h5") + " " + path("ca.h5"));
  EXPECT_EQ(input.code, 3) << input.output;
  EXPECT_NE(input.output.find("these contacts were computed from " + path("a.h5") +
                              " (root attribute input), not from " + path("c.h5")),
            std::string::npos)
      << input.output;
  EXPECT_EQ(lines(input.output), 1u) << input.output;

  // The scene moved to another directory under its name: its contacts still validate.
  fs::create_directory(path("moved"));
  fs::copy_file(path("a.h5"), path("moved/a.h5"));
  const test::CliResult moved = test::run_cli("validate " + path("moved/a.h5") + " " + path("ca.h5"));
  EXPECT_EQ(moved.code, 0) << moved.output;
}

}  // namespace
}  // namespace cg
