// `contactgrid study` end to end at a tiny scale: the CSV's columns, and what today's engine does on
// every family, judged against the exact reference:
//   - fp64 decides every pair outside its band as the reference does, on every family;
//   - no mode is ever wrong without a word: every row has no missed or extra pair outside its band
//     (or the engine refused the scene), and a normal off by more than a degree comes with a flag
//     (fp32's unresolved normals are recomputed in fp64, so none is left);
//   - fp32 writes world positions as float32, so far from the origin its points are off by the float
//     spacing there (a property of the mode, which the study must show).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "study/study.hpp"
#include "study/study_families.hpp"
#include "support/run_cli.hpp"
#include "temp_dir.hpp"

namespace cg::test {
namespace {

using Result = CliResult;
Result run(const std::string& args) { return run_cli(args); }

using Record = std::map<std::string, std::string>;

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  for (std::string f; std::getline(ss, f, ',');) out.push_back(f);
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

class Study : public TempDirTest {
 protected:
  // One tiny study of every family and mode; returns the CSV rows by column name.
  std::vector<Record> run_tiny() {
    const Result r =
        run("study --scale 0.02 --repetitions 1 --csv " + path("s.csv") + " --svg " + path("s.svg"));
    EXPECT_EQ(r.code, 0) << r.output;
    std::ifstream f(path("s.csv"));
    std::string line;
    std::getline(f, line);
    m_header = split(line);
    std::vector<Record> rows;
    while (std::getline(f, line)) {
      const auto fields = split(line);
      EXPECT_EQ(fields.size(), m_header.size()) << line;
      Record rec;
      for (std::size_t i = 0; i < fields.size() && i < m_header.size(); ++i) rec[m_header[i]] = fields[i];
      rows.push_back(rec);
    }
    return rows;
  }
  std::vector<std::string> m_header;
};

TEST_F(Study, TinyStudyMeetsTheInvariantsOnEveryFamily) {
  const std::vector<Record> rows = run_tiny();
  EXPECT_EQ(m_header, split(study_csv_header()));
  EXPECT_EQ(m_header,
            (std::vector<std::string>{"family", "mode", "tolerance", "backend", "bodies", "reference_pairs",
                                      "contacts", "status", "time_s", "repetitions", "band", "missed",
                                      "extra", "borderline", "flagged", "max_position_rel",
                                      "p99_position_rel", "max_normal_deg", "max_distance_err"}));
  std::set<std::string> seen_fp64;
  for (const Record& r : rows) {
    const std::string what =
        r.at("mode") + " " + r.at("family") + " " + r.at("backend") + " tol " + r.at("tolerance");
    ASSERT_TRUE(r.at("status") == "ok" || r.at("status") == "refused") << what;
    EXPECT_GT(std::stoull(r.at("bodies")), 0u) << what;
    if (r.at("mode") == "fp64") {
      EXPECT_EQ(r.at("status"), "ok") << what;
      seen_fp64.insert(r.at("family"));
    }
    if (r.at("status") == "refused") continue;
    EXPECT_EQ(r.at("missed"), "0") << what << ": a contact outside the band was missed";
    EXPECT_EQ(r.at("extra"), "0") << what << ": a pair outside the band was invented";
    EXPECT_GE(std::stod(r.at("time_s")), 0) << what;
    const bool flagged = std::stoull(r.at("flagged")) > 0;
    EXPECT_TRUE(std::stod(r.at("max_normal_deg")) <= 1 || flagged)
        << what << ": normal off by " << r.at("max_normal_deg") << "° unflagged";
    if (r.at("mode") == "fp32" && r.at("family").rfind("far-", 0) == 0) {  // float32 world positions
      EXPECT_GT(std::stod(r.at("max_position_rel")), 1e-3) << what;
    }
  }
  EXPECT_EQ(seen_fp64.size(), study_families().size()) << "fp64 did not run on every family";
  // the plot: one marker per row that ran
  std::ifstream svg(path("s.svg"));
  const std::string text((std::istreambuf_iterator<char>(svg)), std::istreambuf_iterator<char>());
  EXPECT_EQ(text.rfind("<svg", 0), 0u);
  std::size_t markers = 0;
  for (std::size_t at = 0; (at = text.find("<circle cx", at)) != std::string::npos; ++at) ++markers;
  for (std::size_t at = 0; (at = text.find("<rect x", at)) != std::string::npos; ++at) ++markers;
  std::size_t ran = 0;
  for (const Record& r : rows) ran += r.at("status") == "ok";
  EXPECT_EQ(markers, ran + study_mode_names().size());  // + the legend's dot per mode
}

TEST_F(Study, BoundsAreHonouredAndNamesChecked) {
  const Result r =
      run("study --families near-coincident --modes fp64 --backends cpu --scale 0.01 --tolerances 0 "
          "--repetitions 1 --csv " +
          path("one.csv"));
  ASSERT_EQ(r.code, 0) << r.output;
  std::ifstream f(path("one.csv"));
  std::string line;
  int lines = 0;
  while (std::getline(f, line)) ++lines;
  EXPECT_EQ(lines, 2);  // header + one row
  EXPECT_NE(r.output.find("near-coincident"), std::string::npos);
  EXPECT_EQ(run("study --families nope").code, 2);
  EXPECT_EQ(run("study --modes fp16").code, 2);
  EXPECT_EQ(run("study --scale 0").code, 2);
  EXPECT_EQ(run("study --tolerances=-1 --families ellipsoids-tangent").code, 2);
}

}  // namespace
}  // namespace cg::test
