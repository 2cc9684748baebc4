// `contactgrid validate` at any length scale and in bounded memory (issue #36).
//
// The same scenes with every length multiplied by 1e-6, 1e-3, 1, 1e3 and 1e6 must give the same
// verdicts, the same comparison counts and the same Bullet pairs (Bullet's memory is its pairs: a
// manifold each), whole and sampled, for spheres (double Bullet) and ellipsoids (float Bullet). Before
// Bullet worked in the scene's units, grains of radius 1e-3 had every box grown by its 0.02 contact
// breaking threshold: hundreds of pairs per body, gigabytes for a few thousand bodies. Then: a scene
// validated in pieces under a small memory budget gives the whole scene's comparison, and still finds
// a contact taken away; the tolerances are fractions of the pairs' size.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "io/scene_file.hpp"
#include "support/run_cli.hpp"
#include "temp_dir.hpp"
#include "validate/bullet_oracle.hpp"
#include "validate/validate.hpp"
#include "validation/validation_helpers.hpp"

namespace cg {
namespace {

using testing::brute_force_contacts;
using testing::random_scene;

const double kScales[] = {1e-6, 1e-3, 1.0, 1e3, 1e6};

Scene scaled(const Scene& s, double f) {
  Scene out = s;
  for (auto& p : out.sphere_position) p = f * p;
  for (auto& r : out.sphere_radius) r *= f;
  for (auto& p : out.ellipsoid_position) p = f * p;
  for (auto& e : out.ellipsoid_semi_axes) e = f * e;
  out.radius_low.reset();
  out.radius_high.reset();
  return out;
}

// What must not depend on the unit of length.
struct Outcome {
  bool pass;
  std::uint64_t checked, matched, missing, extra, borderline, judged, our_errors, pieces;
  std::uint64_t bullet_pairs;
};
Outcome outcome(const ValidateReport& r) {
  return {
      r.pass,   r.checked,    r.matched, r.missing,     r.extra, r.borderline_missing + r.borderline_extra,
      r.judged, r.our_errors, r.pieces,  r.bullet_pairs};
}

// Bullet's pairs differ a little between units: its frame's scale is the power of two nearest
// 1 / mean radius, so the mean radius there lies anywhere in [0.7, 1.4], and the pairs its contact
// breaking threshold adds with it.
void expect_same(const Outcome& a, const Outcome& b, const std::string& what) {
  EXPECT_EQ(a.pass, b.pass) << what;
  EXPECT_EQ(a.checked, b.checked) << what;
  EXPECT_EQ(a.matched, b.matched) << what;
  EXPECT_EQ(a.missing, b.missing) << what;
  EXPECT_EQ(a.extra, b.extra) << what;
  EXPECT_EQ(a.our_errors, b.our_errors) << what;
  EXPECT_EQ(a.pieces, b.pieces) << what;
  EXPECT_NEAR(double(a.bullet_pairs), double(b.bullet_pairs), 0.05 * double(b.bullet_pairs)) << what;
}

TEST(ValidateScale, SpheresSameVerdictsAndPairsAtEveryUnit) {
  const Scene base = random_scene(3000, testing::edge_for(3000, 1.0), /*seed=*/17);
  for (const bool sampled : {false, true}) {
    std::vector<Outcome> seen;
    for (const double f : kScales) {
      const Scene scene = scaled(base, f);
      const Contacts<double> exact = brute_force_contacts(scene);
      ValidateOptions o;
      if (sampled) o.sample = 3, o.bodies_per_box = 400, o.seed = 5;
      const ValidateReport r = validate(scene, exact, o);
      const std::string what = (sampled ? "sampled, lengths x " : "whole, lengths x ") + std::to_string(f);
      EXPECT_TRUE(r.pass) << what << "\n" << r.text();
      EXPECT_EQ(r.matched, r.checked) << what;
      EXPECT_GT(r.checked, sampled ? 100u : 2000u) << what;
      EXPECT_LT(r.max_position_rel, 1e-12) << what;  // the same formulas: rounding only
      // Bullet's pairs stay a small multiple of the contacts it checks.
      EXPECT_LT(r.bullet_pairs, 3 * r.bullet_contacts + r.largest_piece) << what << "\n" << r.text();
      seen.push_back(outcome(r));
    }
    for (std::size_t k = 1; k < seen.size(); ++k)
      expect_same(seen[k], seen[2],
                  std::string(sampled ? "sampled" : "whole") + ", lengths x " + std::to_string(kScales[k]) +
                      " against x 1");
  }
}

TEST(ValidateScale, MissingContactFoundAtEveryUnit) {
  const Scene base = random_scene(2000, testing::edge_for(2000, 1.0), /*seed=*/23);
  for (const double f : kScales) {
    const Scene scene = scaled(base, f);
    Contacts<double> c = brute_force_contacts(scene);
    std::size_t row = 0;
    while (row < c.size() && !(c.distance[row] < -0.2 * f)) ++row;
    ASSERT_LT(row, c.size());
    testing::erase_row(c, row);
    const ValidateReport r = validate(scene, c, ValidateOptions{});
    EXPECT_FALSE(r.pass) << r.text();
    EXPECT_EQ(r.missing, 1u) << "lengths x " << f << "\n" << r.text();
  }
}

// The position limit is 0.1·L of each pair: a point moved by 0.2·L fails at every unit, and
// --pos-abs makes it a length again.
TEST(ValidateScale, PositionToleranceIsRelativeUnlessAbsoluteIsGiven) {
  const Scene base = random_scene(1500, testing::edge_for(1500, 1.0), /*seed=*/29);
  for (const double f : kScales) {
    const Scene scene = scaled(base, f);
    Contacts<double> c = brute_force_contacts(scene);
    std::size_t row = 0;
    while (row < c.size() && !(c.distance[row] < -0.2 * f)) ++row;
    ASSERT_LT(row, c.size());
    const double L = std::max(scene.sphere_radius[std::size_t(c.id_a[row])],
                              scene.sphere_radius[std::size_t(c.id_b[row])]);
    c.position_on_a[row].y += 0.2 * L;
    ValidateOptions o;
    ValidateReport r = validate(scene, c, o);
    EXPECT_FALSE(r.pass) << r.text();
    EXPECT_NEAR(r.max_position_rel, 0.2, 1e-9);
    EXPECT_NE(r.text().find("position 0.1·L"), std::string::npos) << r.text();
    o.pos_abs = 0.3 * L;
    r = validate(scene, c, o);
    EXPECT_TRUE(r.pass) << r.text();
    o.pos_abs = 0.1 * L;
    r = validate(scene, c, o);
    EXPECT_FALSE(r.pass) << r.text();
    EXPECT_NE(r.text().find("--pos-abs"), std::string::npos) << r.text();
  }
}

// Ellipsoids end to end: the scene file scaled, detect (fp64), validate (float Bullet, the judge).
class ValidateScaleShapes : public test::TempDirTest {};

TEST_F(ValidateScaleShapes, EllipsoidsSameVerdictsAndPairsAtEveryUnit) {
  const auto g = test::run_cli("generate " + path("base.h5") + " --kind mixed -n 1200 --seed 31 -q");
  ASSERT_EQ(g.code, 0) << g.output;
  const Scene base = read_scene(path("base.h5"));
  for (const bool sampled : {false, true}) {
    std::vector<Outcome> seen;
    for (const double f : kScales) {
      const std::string name = "s" + std::to_string(int(std::log10(f)) + 6);
      write_scene(path(name + ".h5"), scaled(base, f));
      const auto d = test::run_cli("detect " + path(name + ".h5") + " -o " + path(name + "_c.h5") +
                                   " --backend cpu --precision fp64 -q");
      ASSERT_EQ(d.code, 0) << d.output;
      ValidateOptions o;
      if (sampled) o.sample = 2, o.bodies_per_box = 300, o.seed = 3;
      const ValidateReport r = validate_files(path(name + ".h5"), path(name + "_c.h5"), o);
      const std::string what = (sampled ? "sampled, lengths x " : "whole, lengths x ") + std::to_string(f);
      EXPECT_TRUE(r.pass) << what << "\n" << r.text();
      EXPECT_EQ(r.bullet, Precision::fp32) << what;
      EXPECT_GT(r.shape_matched, sampled ? 20u : 200u) << what;
      EXPECT_EQ(r.our_errors, 0u) << what << "\n" << r.text();
      EXPECT_LT(r.bullet_pairs, 4 * r.bullet_contacts + r.largest_piece) << what << "\n" << r.text();
      seen.push_back(outcome(r));
    }
    // Float Bullet's own rounding differs with the frame's scale, so its few one-sided answers (shallow
    // misses, Bullet errors) may come and go; the comparison of ours must not.
    for (std::size_t k = 0; k < seen.size(); ++k) {
      const std::string what =
          std::string(sampled ? "sampled" : "whole") + ", lengths x " + std::to_string(kScales[k]);
      EXPECT_EQ(seen[k].pass, seen[2].pass) << what;
      EXPECT_EQ(seen[k].checked, seen[2].checked) << what;
      EXPECT_EQ(seen[k].missing, 0u) << what;
      EXPECT_NEAR(double(seen[k].matched), double(seen[2].matched), 0.01 * double(seen[2].matched)) << what;
      EXPECT_NEAR(double(seen[k].bullet_pairs), double(seen[2].bullet_pairs),
                  0.05 * double(seen[2].bullet_pairs))
          << what;
    }
  }
}

// Pieces: a budget that holds a tenth of the scene's Bullet world cuts it into pieces; the comparison
// is the whole scene's, pair for pair, and a contact taken away is still found.
TEST(ValidatePieces, SmallBudgetGivesTheWholeSceneComparison) {
  const Scene scene = random_scene(6000, testing::edge_for(6000, 2.0), /*seed=*/37);
  Contacts<double> exact = brute_force_contacts(scene);
  const ValidateReport whole = validate(scene, exact, ValidateOptions{});
  ASSERT_TRUE(whole.pass) << whole.text();
  ASSERT_EQ(whole.pieces, 1u);

  ValidateOptions o;
  o.piece_bytes = std::uint64_t(0.1 * (2400.0 * double(whole.bullet_pairs) + 1300.0 * 6000));
  const ValidateReport cut = validate(scene, exact, o);
  EXPECT_TRUE(cut.pass) << cut.text();
  EXPECT_GE(cut.pieces, 10u) << cut.text();
  EXPECT_LT(cut.largest_piece, 1500u) << cut.text();
  EXPECT_EQ(cut.checked, whole.checked);
  EXPECT_EQ(cut.matched, whole.matched);
  EXPECT_EQ(cut.bullet_contacts, whole.bullet_contacts);  // each pair compared once
  EXPECT_LT(cut.max_position_error, 1e-12);               // each piece has its own origin: rounding only
  EXPECT_NE(cut.text().find(std::to_string(cut.pieces) + " pieces"), std::string::npos) << cut.text();

  std::size_t row = exact.size() / 2;
  while (row < exact.size() && !(exact.distance[row] < -0.2)) ++row;
  ASSERT_LT(row, exact.size());
  testing::erase_row(exact, row);
  const ValidateReport holes = validate(scene, exact, o);
  EXPECT_FALSE(holes.pass);
  EXPECT_EQ(holes.missing, 1u) << holes.text();
}

TEST(ValidatePieces, MemoryLimitBelowWhatIsHeldIsRefused) {
  const Scene scene = random_scene(500, testing::edge_for(500), /*seed=*/41);
  ValidateOptions o;
  o.memory_limit = 1 << 20;  // 1 MiB: less than the process itself
  try {
    validate(scene, brute_force_contacts(scene), o);
    ADD_FAILURE() << "a 1 MiB limit was accepted";
  } catch (const UsageError& e) {
    EXPECT_NE(std::string(e.what()).find("--memory 1 MiB"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("give at least"), std::string::npos) << e.what();
  }
  EXPECT_EQ(parse_memory("4G"), std::uint64_t(4) << 30);
  EXPECT_EQ(parse_memory("512M"), std::uint64_t(512) << 20);
  EXPECT_EQ(parse_memory("1.5GiB"), std::uint64_t(3) << 29);
  EXPECT_EQ(parse_memory("2gb"), std::uint64_t(2) << 30);
  EXPECT_EQ(parse_memory("1000000"), 1000000u);
  EXPECT_THROW(parse_memory("lots"), UsageError);
  EXPECT_THROW(parse_memory("4X"), UsageError);
  EXPECT_THROW(parse_memory("-1G"), UsageError);
  EXPECT_GT(default_memory_limit(), 0u);
  EXPECT_LE(default_memory_limit(), std::uint64_t(4) << 30);
}

TEST(BulletFrame, ScaleIsThePowerOfTwoNearestTheInverseMeanRadius) {
  EXPECT_EQ(bullet_scale(1.0), 1.0);
  EXPECT_EQ(bullet_scale(0.75), 1.0);
  EXPECT_EQ(bullet_scale(0.004), 256.0);
  EXPECT_EQ(bullet_scale(1e6), std::ldexp(1.0, -20));
  for (double r = 1e-7; r < 1e7; r *= 3.7) {
    const double s = bullet_scale(r);
    int exponent = 0;
    EXPECT_EQ(std::frexp(s, &exponent), 0.5) << r;  // a power of two: exact scaling
    EXPECT_GE(r * s, 0.70) << r;
    EXPECT_LE(r * s, 1.42) << r;
  }
  EXPECT_THROW(bullet_scale(0), Error);
}

}  // namespace
}  // namespace cg
