// generate --kind ellipsoids | mixed: valid, seeded, streamed = in memory, the density of the bounding
// spheres, the options checked.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <variant>

#include "io/scene_file.hpp"
#include "scene/generate.hpp"
#include "temp_dir.hpp"

namespace {

using cg::GenerateOptions;
using cg::Scene;

class GenerateShapes : public cg::test::TempDirTest {};

GenerateOptions options(const std::string& kind, std::uint64_t n, std::uint64_t seed = 7) {
  GenerateOptions o;
  o.kind = kind;
  o.count = n;
  o.seed = seed;
  o.radius_low = 0.25;
  o.radius_high = 1.0;
  return o;
}

void expect_valid_ellipsoids(const Scene& s, double lo, double hi) {
  for (std::size_t j = 0; j < s.ellipsoid_count(); ++j) {
    const auto& a = s.ellipsoid_semi_axes[j];
    for (double v : {a.x, a.y, a.z}) {
      EXPECT_GE(v, lo);
      EXPECT_LE(v, hi);
    }
    const auto& q = s.ellipsoid_orientation[j];
    EXPECT_NEAR(std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), 1.0, 1e-12);
  }
}

TEST_F(GenerateShapes, EllipsoidKind) {
  const Scene s = cg::generate_scene(options("ellipsoids", 500));
  EXPECT_EQ(s.sphere_count(), 0u);
  ASSERT_EQ(s.ellipsoid_count(), 500u);
  expect_valid_ellipsoids(s, 0.25, 1.0);
  EXPECT_EQ(std::get<std::string>(s.attributes.at("generator")), "ellipsoids");
  EXPECT_EQ(std::get<std::int64_t>(s.attributes.at("ellipsoids")), 500);
  EXPECT_EQ(s.radius_low, 0.25);
  EXPECT_EQ(s.radius_high, 1.0);
}

TEST_F(GenerateShapes, MixedKindSpheresThenEllipsoids) {
  GenerateOptions o = options("mixed", 1000);
  o.ellipsoid_fraction = 0.3;
  EXPECT_EQ(cg::generated_ellipsoids(o), 300u);
  const Scene s = cg::generate_scene(o);
  EXPECT_EQ(s.sphere_count(), 700u);
  EXPECT_EQ(s.ellipsoid_count(), 300u);
  expect_valid_ellipsoids(s, 0.25, 1.0);
  EXPECT_EQ(std::get<double>(s.attributes.at("ellipsoid_fraction")), 0.3);
  EXPECT_EQ(std::get<std::int64_t>(s.attributes.at("spheres")), 700);
}

TEST_F(GenerateShapes, SeededAndStreamedEqualsInMemory) {
  GenerateOptions o = options("mixed", 3000, 99);
  o.ellipsoid_fraction = 0.6;
  cg::generate_scene_file(path("m.h5"), o);
  const Scene file = cg::read_scene(path("m.h5"));
  const Scene mem = cg::generate_scene(o);
  ASSERT_EQ(file.ellipsoid_count(), mem.ellipsoid_count());
  ASSERT_EQ(file.sphere_count(), mem.sphere_count());
  for (std::size_t j = 0; j < mem.ellipsoid_count(); ++j) {
    EXPECT_TRUE(file.ellipsoid_position[j] == mem.ellipsoid_position[j]);
    EXPECT_TRUE(file.ellipsoid_semi_axes[j] == mem.ellipsoid_semi_axes[j]);
    EXPECT_EQ(file.ellipsoid_orientation[j], mem.ellipsoid_orientation[j]);
  }
  for (std::size_t i = 0; i < mem.sphere_count(); ++i) EXPECT_EQ(file.sphere_radius[i], mem.sphere_radius[i]);
  EXPECT_EQ(std::get<std::int64_t>(file.attributes.at("seed")), 99);
  const Scene other = cg::generate_scene(options("mixed", 3000, 100));
  EXPECT_FALSE(other.ellipsoid_position[0] == mem.ellipsoid_position[0]);
}

// Bounding-sphere overlaps per body close to --contacts-per-body (the density uses the bounding radius).
double bounding_pairs_per_body(const Scene& s) {
  std::vector<cg::Vec3<double>> c(s.sphere_position.begin(), s.sphere_position.end());
  std::vector<double> r(s.sphere_radius.begin(), s.sphere_radius.end());
  for (std::size_t j = 0; j < s.ellipsoid_count(); ++j) {
    const auto& a = s.ellipsoid_semi_axes[j];
    c.push_back(s.ellipsoid_position[j]);
    r.push_back(std::max({a.x, a.y, a.z}));
  }
  std::size_t pairs = 0;
  for (std::size_t i = 0; i < c.size(); ++i)
    for (std::size_t k = i + 1; k < c.size(); ++k) {
      const double dx = c[i].x - c[k].x, dy = c[i].y - c[k].y, dz = c[i].z - c[k].z;
      pairs += dx * dx + dy * dy + dz * dz <= (r[i] + r[k]) * (r[i] + r[k]);
    }
  return double(pairs) / double(c.size());
}

TEST_F(GenerateShapes, DensityFromTheBoundingRadius) {
  for (const char* kind : {"ellipsoids", "mixed"}) {
    GenerateOptions o = options(kind, 6000, 3);
    o.contacts_per_body = 0.8;
    EXPECT_NEAR(bounding_pairs_per_body(cg::generate_scene(o)), 0.8, 0.12) << kind;
  }
}

TEST_F(GenerateShapes, OptionsChecked) {
  GenerateOptions o = options("mixed", 10);
  o.ellipsoid_fraction = 1.5;
  EXPECT_THROW(cg::validate_generate_options(o), cg::UsageError);
  o.ellipsoid_fraction = 0;
  EXPECT_EQ(cg::generate_scene(o).ellipsoid_count(), 0u);
  EXPECT_THROW(cg::validate_generate_options(options("cubes", 10)), cg::UsageError);
}

}  // namespace
