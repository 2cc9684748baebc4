// Tests of `contactgrid validate` (src/validate/validate.hpp) and of the Bullet oracle it stands on.
// Contacts are built by brute force with the docs/FORMAT.md §3 formulas (validation_helpers.hpp), never by
// the engine, then corrupted one way at a time; each corruption must FAIL for its own reason.
#include "validate/validate.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "validate/bullet_oracle.hpp"
#include "validation/validation_helpers.hpp"

namespace cg {
namespace {

using testing::brute_force_contacts;
using testing::random_scene;

bool has_failure(const ValidateReport& r, const std::string& word) {
  for (const auto& f : r.failures)
    if (f.find(word) != std::string::npos) return true;
  return false;
}

// Row of a contact with distance < -limit (deep: never borderline).
std::size_t deep_row(const Contacts<double>& c, double limit = 0.1) {
  for (std::size_t r = 0; r < c.size(); ++r)
    if (c.distance[r] < -limit) return r;
  ADD_FAILURE() << "no deep contact";
  return 0;
}

class ValidateTest : public ::testing::Test {
 protected:
  void SetUp() override {
    scene = random_scene(3000, testing::edge_for(3000), /*seed=*/11);
    exact = brute_force_contacts(scene);
    ASSERT_GT(exact.size(), 500u);
  }
  Scene scene;
  Contacts<double> exact;
  ValidateOptions options;
};

TEST_F(ValidateTest, CorrectContactsPass) {
  const ValidateReport r = validate(scene, exact, options);
  EXPECT_TRUE(r.pass) << r.text();
  EXPECT_EQ(r.missing + r.extra, 0u);
  EXPECT_EQ(r.matched, exact.size());
  EXPECT_EQ(r.checked, exact.size());
  EXPECT_DOUBLE_EQ(r.checked_fraction(), 1.0);
  EXPECT_LT(r.max_position_error, 1e-9);
  EXPECT_LT(r.max_angle_deg, 1e-6);
  EXPECT_LT(r.max_distance_error, 1e-9);
  EXPECT_NE(r.text().find("validate: PASS"), std::string::npos);
  EXPECT_NE(r.text().find("100.00%"), std::string::npos);
}

TEST_F(ValidateTest, RemovedContactFailsMissing) {
  const std::size_t row = deep_row(exact);
  const auto a = exact.id_a[row], b = exact.id_b[row];
  testing::erase_row(exact, row);
  const ValidateReport r = validate(scene, exact, options);
  EXPECT_FALSE(r.pass);
  EXPECT_EQ(r.missing, 1u);
  EXPECT_EQ(r.extra, 0u);
  EXPECT_TRUE(has_failure(r, "missing")) << r.text();
  ASSERT_FALSE(r.offenders.empty());
  EXPECT_EQ(r.offenders[0].kind, ValidateOffender::Kind::missing);
  EXPECT_EQ(r.offenders[0].id_a, a);
  EXPECT_EQ(r.offenders[0].id_b, b);
  EXPECT_NE(r.text().find("validate: FAIL"), std::string::npos);
}

TEST_F(ValidateTest, AddedContactFailsExtra) {
  // A pair clearly apart (distance > 0.5): its contact by the formulas, inserted in sorted place.
  std::int64_t a = -1, b = -1;
  for (std::int64_t j = 1; j < std::int64_t(scene.sphere_count()) && a < 0; ++j) {
    const Vec3<double> d = scene.sphere_position[0] - scene.sphere_position[std::size_t(j)];
    if (std::sqrt(dot(d, d)) - scene.sphere_radius[0] - scene.sphere_radius[std::size_t(j)] > 0.5)
      a = 0, b = j;
  }
  ASSERT_GE(a, 0);
  testing::push_contact(exact, scene, a, b);
  std::size_t pos = 0;
  while (pos + 1 < exact.size() && std::pair(exact.id_a[pos], exact.id_b[pos]) < std::pair(a, b)) ++pos;
  testing::move_last_to(exact, pos);
  const ValidateReport r = validate(scene, exact, options);
  EXPECT_FALSE(r.pass);
  EXPECT_EQ(r.extra, 1u);
  EXPECT_EQ(r.missing, 0u);
  EXPECT_EQ(r.unsorted, 0u);
  EXPECT_TRUE(has_failure(r, "extra")) << r.text();
}

TEST_F(ValidateTest, FlippedNormalFailsAngle) {
  const std::size_t row = deep_row(exact);
  exact.normal_on_b[row] = -exact.normal_on_b[row];
  const ValidateReport r = validate(scene, exact, options);
  EXPECT_FALSE(r.pass);
  EXPECT_NEAR(r.max_angle_deg, 180.0, 1e-6);
  EXPECT_TRUE(has_failure(r, "angle")) << r.text();
  EXPECT_FALSE(has_failure(r, "position"));
  EXPECT_EQ(r.missing + r.extra, 0u);
}

TEST_F(ValidateTest, MovedPointFailsPosition) {
  const std::size_t row = deep_row(exact);
  exact.position_on_a[row].y += 2 * options.pos_eps;
  const ValidateReport r = validate(scene, exact, options);
  EXPECT_FALSE(r.pass);
  EXPECT_NEAR(r.max_position_error, 2 * options.pos_eps, 1e-9);
  EXPECT_TRUE(has_failure(r, "position")) << r.text();
  EXPECT_FALSE(has_failure(r, "angle"));
}

TEST_F(ValidateTest, SwappedBodiesFailIdOrder) {
  // A and B exchanged in one row, consistently (points swapped, normal negated): the geometry still
  // matches Bullet, only docs/FORMAT.md §2's id order is broken.
  const std::size_t row = deep_row(exact);
  std::swap(exact.id_a[row], exact.id_b[row]);
  std::swap(exact.position_on_a[row], exact.position_on_b[row]);
  exact.normal_on_b[row] = -exact.normal_on_b[row];
  const ValidateReport r = validate(scene, exact, options);
  EXPECT_FALSE(r.pass);
  EXPECT_EQ(r.bad_id_order, 1u);
  EXPECT_TRUE(has_failure(r, "id_a < id_b")) << r.text();
  EXPECT_EQ(r.missing + r.extra, 0u);
  EXPECT_LT(r.max_position_error, 1e-9);
}

TEST_F(ValidateTest, UnsortedAndDuplicateRowsFail) {
  Contacts<double> dup = exact;
  testing::push_contact(dup, scene, exact.id_a[5], exact.id_b[5]);
  testing::move_last_to(dup, 6);  // row 6 repeats row 5
  ValidateReport r = validate(scene, dup, options);
  EXPECT_FALSE(r.pass);
  EXPECT_EQ(r.duplicates, 1u);
  EXPECT_TRUE(has_failure(r, "duplicates")) << r.text();

  Contacts<double> unsorted = exact;
  testing::push_contact(unsorted, scene, exact.id_a[0], exact.id_b[0]);
  testing::erase_row(unsorted, 0);  // first pair moved to the end
  r = validate(scene, unsorted, options);
  EXPECT_FALSE(r.pass);
  EXPECT_EQ(r.unsorted, 1u);
  EXPECT_TRUE(has_failure(r, "not sorted")) << r.text();
  EXPECT_EQ(r.missing + r.extra, 0u);  // still compared, in canonical order
}

TEST_F(ValidateTest, BadOptionsAndLengthsThrow) {
  ValidateOptions bad = options;
  bad.pos_eps = 0;
  EXPECT_THROW(validate(scene, exact, bad), UsageError);
  EXPECT_THROW(parse_bullet_precision("quad"), UsageError);
  EXPECT_EQ(parse_bullet_precision("float"), Precision::fp32);
  Contacts<double> broken = exact;
  broken.distance.pop_back();
  EXPECT_THROW(validate(scene, broken, options), InputError);
}

TEST(BulletOracle, ConventionsAndIdOrder) {
  // Three spheres; ids given non-contiguous to check the id mapping.
  OracleBodies s;
  s.position = {{0, 0, 0}, {1.5, 0, 0}, {10, 10, 10}};
  s.radius = {1.0, 0.75, 0.5};
  s.id = {4, 9, 12};
  for (Precision p : {Precision::fp64, Precision::fp32}) {
    const OracleResult r = bullet_collide(s, p, /*warm_step=*/true);
    EXPECT_EQ(r.scalar_bytes, p == Precision::fp64 ? 8 : 4);
    EXPECT_GE(r.warm_seconds, 0);
    ASSERT_EQ(r.contacts.size(), 1u);
    EXPECT_EQ(r.contacts.id_a[0], 4);
    EXPECT_EQ(r.contacts.id_b[0], 9);
    // n from B to A = (-1, 0, 0); distance 1.5 - 1.75; position_on_b = b + rb n.
    EXPECT_NEAR(r.contacts.normal_on_b[0].x, -1, 1e-6);
    EXPECT_NEAR(r.contacts.distance[0], -0.25, 1e-6);
    EXPECT_NEAR(r.contacts.position_on_b[0].x, 0.75, 1e-6);
    EXPECT_NEAR(r.contacts.position_on_a[0].x, 1.0, 1e-6);
  }
}

TEST(BulletOracle, FloatExecutableIsFound) { EXPECT_FALSE(bullet_float_executable().empty()); }

// Why validate hands Bullet a frame centred on the bodies: far from the origin float Bullet rounds
// every centre to 1/16 (ulp of 1e6 in float), so in world coordinates it misses and invents contacts
// and turns normals; centred on the bodies it agrees with the exact contacts, like double Bullet.
TEST(BulletPrecision, FloatBulletWrongFarFromOriginRightInTheCentredFrame) {
  const Vec3<double> offset{1e6, 1e6, 1e6};
  Scene scene = random_scene(1500, testing::edge_for(1500, 1.0), /*seed=*/5, offset);
  // A nearly coincident pair (centres 0.028 apart along (0, 1, 1)): float rounds both world centres
  // to the same point, so float Bullet's normal there is its default (1, 0, 0), 90° off the exact one.
  scene.sphere_position.push_back({1e6 + 0.5, 1e6 + 0.5, 1e6 + 0.5});
  scene.sphere_radius.push_back(0.6);
  scene.sphere_position.push_back({1e6 + 0.5, 1e6 + 0.52, 1e6 + 0.52});
  scene.sphere_radius.push_back(0.6);
  const Contacts<double> exact = brute_force_contacts(scene);

  // Float Bullet in world coordinates (origin 0, scale 1).
  std::vector<std::int64_t> all(scene.size());
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = std::int64_t(i);
  double extent = 0;
  OracleBodies world = oracle_bodies(scene, all, 1.0, extent);
  world.origin = {0, 0, 0};
  const OracleResult wrong = bullet_collide(world, Precision::fp32);
  std::size_t differ = 0;
  double worst_angle = 0;
  {
    std::size_t i = 0, j = 0;
    while (i < exact.size() || j < wrong.contacts.size()) {
      const auto ke =
          i < exact.size() ? std::pair(exact.id_a[i], exact.id_b[i]) : std::pair(INT64_MAX, INT64_MAX);
      const auto kw = j < wrong.contacts.size() ? std::pair(wrong.contacts.id_a[j], wrong.contacts.id_b[j])
                                                : std::pair(INT64_MAX, INT64_MAX);
      if (ke == kw) {
        const Vec3<double> a = exact.normal_on_b[i], b = wrong.contacts.normal_on_b[j];
        worst_angle = std::max(worst_angle, std::acos(std::clamp(dot(a, b), -1.0, 1.0)) * 180 / M_PI);
        ++i, ++j;
      } else {
        ++differ;
        ke < kw ? ++i : ++j;
      }
    }
  }
  EXPECT_GT(differ, 0u) << "float Bullet in world coordinates found exactly the exact pairs";
  EXPECT_GT(worst_angle, 45.0);

  ValidateOptions o;
  const ValidateReport dbl = validate(scene, exact, o);
  EXPECT_TRUE(dbl.pass) << dbl.text();
  o.bullet = Precision::fp32;
  const ValidateReport flt = validate(scene, exact, o);
  EXPECT_TRUE(flt.pass) << flt.text();
  EXPECT_EQ(flt.matched, exact.size());
  EXPECT_LT(flt.max_angle_deg, 0.1) << flt.text();
}

TEST(ValidateSampling, FiftyThousandBodiesPassWithFraction) {
  const std::size_t n = 50000;
  const Scene scene = random_scene(n, testing::edge_for(n), /*seed=*/21);
  const Contacts<double> exact = brute_force_contacts(scene);
  ValidateOptions o;
  o.sample = 4;
  o.seed = 3;
  const ValidateReport r = validate(scene, exact, o);
  EXPECT_TRUE(r.pass) << r.text();
  EXPECT_EQ(r.sample_boxes, 4u);
  EXPECT_GT(r.checked, 0u);
  EXPECT_GT(r.checked_fraction(), 0.0);
  EXPECT_LE(r.checked_fraction(), 1.0);
  EXPECT_EQ(r.matched, r.checked);
  EXPECT_NE(r.text().find("4 sampled sub-boxes"), std::string::npos);

  // One box checks a part only, and still sees contacts missing inside it.
  ValidateOptions one = o;
  one.sample = 1;
  const ValidateReport base = validate(scene, exact, one);
  ASSERT_TRUE(base.pass) << base.text();
  ASSERT_GT(base.matched, 0u);
  EXPECT_LT(base.checked_fraction(), 1.0);
  Contacts<double> thinned = exact;
  for (std::size_t row = thinned.size(); row-- > 0;)
    if (row % 3 == 0 && thinned.distance[row] < -0.1) testing::erase_row(thinned, row);
  const ValidateReport holes = validate(scene, thinned, one);
  EXPECT_FALSE(holes.pass);
  EXPECT_GT(holes.missing, 0u) << holes.text();
}

}  // namespace
}  // namespace cg
