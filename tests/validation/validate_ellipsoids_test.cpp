// `contactgrid validate` on ellipsoid and mixed scenes (issue #12): Bullet's ellipsoid shape on
// pairs whose contact is known in closed form, and the command end to end (generate, detect,
// validate), on honest contacts and on files with one ellipsoid contact corrupted.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "io/contact_file.hpp"
#include "support/run_cli.hpp"
#include "temp_dir.hpp"
#include "validate/bullet_oracle.hpp"

namespace cg {
namespace {

// Two ellipsoids on the x axis, 1.4 apart: A (1, 0.5, 0.5) unrotated, B the same turned 90° about z
// (long axis along y). Along x the supports are 1 and 0.5, so they overlap by 0.1 there, and no
// direction is shallower (along y: 0.5 + 1; along z: 0.5 + 0.5 − 0 = 1 > 0.1 − …): distance −0.1,
// n = (−1, 0, 0) from B (at x = 1.4) towards A, position_on_b = (0.9, 0, 0).
OracleBodies crossed_pair(Vec3<double> offset) {
  const double s = std::sqrt(0.5);
  OracleBodies b;
  b.position = {offset, offset + Vec3<double>{1.4, 0, 0}};
  b.radius = {1.0, 1.0};
  b.semi_axes = {{1, 0.5, 0.5}, {1, 0.5, 0.5}};
  b.orientation = {{1, 0, 0, 0}, {s, 0, 0, s}};
  b.id = {3, 8};
  return b;
}

TEST(BulletEllipsoid, ExactSupportGivesTheClosedFormContact) {
  for (const Precision p : {Precision::fp64, Precision::fp32}) {
    const OracleResult r = bullet_collide(crossed_pair({0, 0, 0}), p);
    ASSERT_EQ(r.contacts.size(), 1u) << "Bullet " << (p == Precision::fp64 ? "double" : "float");
    EXPECT_EQ(r.contacts.id_a[0], 3);
    EXPECT_EQ(r.contacts.id_b[0], 8);
    EXPECT_NEAR(r.contacts.distance[0], -0.1, 1e-3);
    EXPECT_NEAR(r.contacts.normal_on_b[0].x, -1, 1e-4);
    EXPECT_NEAR(r.contacts.position_on_b[0].x, 0.9, 1e-3);
    EXPECT_NEAR(r.contacts.position_on_a[0].x, 1.0, 1e-3);
  }
}

// Float Bullet rounds 1e6 + 1.4 to 1e6 + 1.375: in world coordinates the same pair is 0.025 off;
// in the frame the validation gives it (origin at the bodies) it is exact again.
TEST(BulletEllipsoid, FloatBulletNeedsTheLocalFrameFarFromTheOrigin) {
  const Vec3<double> far{1e6, -1e6, 1e6};
  OracleBodies world = crossed_pair(far);
  const OracleResult wrong = bullet_collide(world, Precision::fp32);
  ASSERT_EQ(wrong.contacts.size(), 1u);
  EXPECT_GT(std::abs(wrong.contacts.distance[0] + 0.1), 0.01);

  OracleBodies framed = crossed_pair(far);
  framed.origin = far + Vec3<double>{0.7, 0, 0};
  const OracleResult right = bullet_collide(framed, Precision::fp32);
  ASSERT_EQ(right.contacts.size(), 1u);
  EXPECT_NEAR(right.contacts.distance[0], -0.1, 1e-3);
  EXPECT_NEAR(right.contacts.position_on_b[0].x - far.x, 0.9, 1e-3);  // moved back to the world
}

using CliRun = test::CliResult;
CliRun run(const std::string& args) { return test::run_cli(args); }

class ValidateShapes : public test::TempDirTest {
 protected:
  // generate + detect (CPU) into s.h5 and c.h5.
  void generate_and_detect(const std::string& generate, const std::string& detect = "") {
    const CliRun g = run("generate " + path("s.h5") + " " + generate + " -q");
    ASSERT_EQ(g.code, 0) << g.output;
    const CliRun d = run("detect " + path("s.h5") + " -o " + path("c.h5") + " --backend cpu " + detect);
    ASSERT_EQ(d.code, 0) << d.output;
  }
  // Writes `c` as a contact file of this scene and validates it.
  CliRun validate_with(const Contacts<double>& c, std::uint64_t bodies) {
    RunInfo info;
    info.bodies = bodies;
    info.precision = "fp64";
    info.backend = "cpu";
    write_contacts(path("bad.h5"), c, info);
    return run("validate " + path("s.h5") + " " + path("bad.h5"));
  }
};

TEST_F(ValidateShapes, GeneratedEllipsoidSceneValidatesPass) {
  ASSERT_NO_FATAL_FAILURE(generate_and_detect("--kind ellipsoids -n 6000 --seed 7"));
  const CliRun v = run("validate " + path("s.h5") + " " + path("c.h5"));
  EXPECT_EQ(v.code, 0) << v.output;
  EXPECT_NE(v.output.find("validate: PASS (Bullet float"), std::string::npos) << v.output;
  EXPECT_NE(v.output.find("ellipsoid pairs: matched"), std::string::npos) << v.output;
  EXPECT_NE(v.output.find("our errors 0"), std::string::npos) << v.output;
  // Double Bullet degenerates on many ellipsoid pairs: each is judged a Bullet error, the run passes.
  const CliRun dbl = run("validate " + path("s.h5") + " " + path("c.h5") + " --bullet double");
  EXPECT_EQ(dbl.code, 0) << dbl.output;
  EXPECT_NE(dbl.output.find("Bullet double"), std::string::npos) << dbl.output;
  EXPECT_EQ(dbl.output.find("Bullet errors 0 "), std::string::npos) << dbl.output;
}

TEST_F(ValidateShapes, GeneratedMixedSceneValidatesPass) {
  ASSERT_NO_FATAL_FAILURE(generate_and_detect("--kind mixed -n 6000 --seed 8", "--precision fp32"));
  const CliRun v = run("validate " + path("s.h5") + " " + path("c.h5"));
  EXPECT_EQ(v.code, 0) << v.output;
  EXPECT_NE(v.output.find("validate: PASS"), std::string::npos) << v.output;
  EXPECT_NE(v.output.find("sphere pairs: max position error"), std::string::npos) << v.output;
  EXPECT_NE(v.output.find("ellipsoid pairs: matched"), std::string::npos) << v.output;
}

class CorruptedContact : public ValidateShapes {
 protected:
  void SetUp() override {
    ValidateShapes::SetUp();
    ASSERT_NO_FATAL_FAILURE(generate_and_detect("--kind mixed -n 3000 --seed 9"));
    contacts = read_contacts(path("c.h5")).contacts;
    spheres = 1500;                              // mixed, fraction 0.5: spheres 0 … 1499, then ellipsoids
    for (row = 0; row < contacts.size(); ++row)  // a deep contact of two ellipsoids
      if (contacts.id_a[row] >= std::int64_t(spheres) && contacts.distance[row] < -0.2) break;
    ASSERT_LT(row, contacts.size());
    pair = "(" + std::to_string(contacts.id_a[row]) + ", " + std::to_string(contacts.id_b[row]) + ")";
    const CliRun ok = validate_with(contacts, 3000);
    ASSERT_EQ(ok.code, 0) << "the uncorrupted copy must pass: " << ok.output;
  }
  void expect_fails_naming_the_pair(const CliRun& r) {
    EXPECT_EQ(r.code, 1) << r.output;
    EXPECT_NE(r.output.find("validate: FAIL"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("FAIL judged wrong: 1 of our ellipsoid contacts"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("ours wrong " + pair), std::string::npos) << r.output;
  }
  Contacts<double> contacts;
  std::size_t spheres = 0, row = 0;
  std::string pair;
};

TEST_F(CorruptedContact, NormalTurnedThirtyDegreesFails) {
  Vec3<double>& n = contacts.normal_on_b[row];
  // Turn n by 30° about an axis perpendicular to it.
  const Vec3<double> helper = std::abs(n.x) < 0.6 ? Vec3<double>{1, 0, 0} : Vec3<double>{0, 1, 0};
  Vec3<double> k = cross(n, helper);
  k = (1 / std::sqrt(dot(k, k))) * k;
  const double t = 30 * 3.141592653589793 / 180;
  n = std::cos(t) * n + std::sin(t) * cross(k, n);
  const CliRun r = validate_with(contacts, 3000);
  expect_fails_naming_the_pair(r);
  EXPECT_NE(r.output.find("surface normal"), std::string::npos) << r.output;
}

TEST_F(CorruptedContact, DistanceChangedFails) {
  contacts.distance[row] -= 0.15;
  const CliRun r = validate_with(contacts, 3000);
  expect_fails_naming_the_pair(r);
  EXPECT_NE(r.output.find("n·distance"), std::string::npos) << r.output;
}

TEST_F(CorruptedContact, RemovedEllipsoidContactFailsMissing) {
  auto drop = [&](auto& v) { v.erase(v.begin() + std::ptrdiff_t(row)); };
  drop(contacts.id_a), drop(contacts.id_b), drop(contacts.position_on_a), drop(contacts.position_on_b);
  drop(contacts.normal_on_b), drop(contacts.distance);
  const CliRun r = validate_with(contacts, 3000);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("FAIL missing: 1 pairs"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("missing  " + pair), std::string::npos) << r.output;
}

}  // namespace
}  // namespace cg
