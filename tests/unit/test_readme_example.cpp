// The README's library example, compiled and run. The region between the EXAMPLE markers must appear
// verbatim in README.md (checked below), so the documentation cannot drift from code that works.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <string>

// EXAMPLE-BEGIN
#include <vector>

#include "engine.hpp"  // target cg_kernels

// Contacts of three spheres: 0 and 1 overlap by 0.1, 2 is alone.
std::size_t count_contacts_example() {
  std::vector<cg::Vec3<double>> centre{{0, 0, 0}, {1.9, 0, 0}, {10, 0, 0}};
  std::vector<double> radius{1.0, 1.0, 0.5};

  cg::EngineOptions options;           // backend auto: CUDA when a GPU is present
  options.fields = cg::Fields::basic;  // or Fields::full for local points and friction directions
  cg::Engine<double> engine(options);  // keep it: buffers are reused by every detect() call

  cg::Contacts<double> c = engine.detect(cg::BodiesView{centre, radius, {}, {}});
  // c.id_a[0] == 0, c.id_b[0] == 1, c.distance[0] == -0.1, c.normal_on_b[0] == (-1, 0, 0)
  return c.size();
}
// EXAMPLE-END

TEST(Readme, LibraryExampleRuns) { EXPECT_EQ(count_contacts_example(), 1u); }

TEST(Readme, LibraryExampleIsInTheReadme) {
  // (not __FILE__: ccache's CCACHE_BASEDIR makes it relative to the build directory)
  std::ifstream self(std::string(CG_SOURCE_DIR) + "/tests/unit/test_readme_example.cpp"),
      readme(std::string(CG_SOURCE_DIR) + "/README.md");
  ASSERT_TRUE(self && readme);
  std::stringstream a, b;
  a << self.rdbuf();
  b << readme.rdbuf();
  const std::string src = a.str();
  const auto begin = src.find("// EXAMPLE-BEGIN\n") + 17, end = src.find("// EXAMPLE-END");
  const std::string example = src.substr(begin, end - begin);
  EXPECT_NE(b.str().find(example), std::string::npos)
      << "README.md does not contain the example of " << __FILE__;
}
