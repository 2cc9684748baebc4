// The library examples of the README and docs/LIBRARY.md, compiled and run. The regions between the
// markers must appear verbatim in those files (checked below), so the documentation cannot drift from
// code that works.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "support/paths.hpp"

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

// SKIN-EXAMPLE-BEGIN
// A simulation loop with a skin: sphere 0 drifts towards sphere 1 by 1/64 per step. The candidates
// of the first call serve while the motion since their build is within skin/2 (steps 1-4), step 5
// rebuilds them, steps 6-7 reuse the new list; every call returns the contacts of a skin-0 call.
std::uint64_t skin_steps_example() {
  std::vector<cg::Vec3<double>> centre{{0, 0, 0}, {2.0625, 0, 0}, {10, 0, 0}};
  std::vector<double> radius{1.0, 1.0, 0.5};
  cg::Engine<double> engine({.skin = 0.125});  // candidates kept while motion <= skin/2
  engine.set_resident(cg::BodiesView{centre, radius, {}, {}});
  for (int step = 0; step < 8; ++step) {
    centre[0].x += 1.0 / 64;  // the integrator's positions
    engine.write_resident(0, centre.size(), centre.data(), radius.data());
    std::size_t k = engine.detect_resident();  // 0 before step 3, then 1: (0, 1) touch
    if (k != (step >= 3 ? 1u : 0u)) return 0;
  }
  return engine.stats().candidate_reuses;  // 6 (and candidate_builds 2)
}
// SKIN-EXAMPLE-END

TEST(Readme, LibraryExampleRuns) { EXPECT_EQ(count_contacts_example(), 1u); }

TEST(Readme, SkinExampleRuns) { EXPECT_EQ(skin_steps_example(), 6u); }

TEST(Readme, LibraryExamplesAreInTheDocs) {
  // By source_dir(), not __FILE__: with CCACHE_BASEDIR set, ccache makes __FILE__ relative to the
  // build directory, which is not CTest's working directory.
  auto text = [](const std::string& relative) {
    std::ifstream in(cg::test::source_dir() + "/" + relative);
    std::stringstream all;
    all << in.rdbuf();
    return std::make_pair(static_cast<bool>(in), all.str());
  };
  const auto [self_read, src] = text("tests/unit/test_readme_example.cpp");
  ASSERT_TRUE(self_read);
  // Each example and the pages that show it: the README's front page and the library page.
  const std::pair<const char*, std::vector<std::string>> examples[] = {
      {"EXAMPLE", {"README.md", "docs/LIBRARY.md"}}, {"SKIN-EXAMPLE", {"docs/LIBRARY.md"}}};
  for (const auto& [marker, pages] : examples) {
    const std::string open = std::string("// ") + marker + "-BEGIN\n";
    const auto begin = src.find(open) + open.size(), end = src.find(std::string("// ") + marker + "-END");
    const std::string example = src.substr(begin, end - begin);
    for (const std::string& page : pages) {
      const auto [read, doc] = text(page);
      ASSERT_TRUE(read) << page;
      EXPECT_NE(doc.find(example), std::string::npos)
          << page << " does not contain the " << marker << " of tests/unit/test_readme_example.cpp";
    }
  }
}
