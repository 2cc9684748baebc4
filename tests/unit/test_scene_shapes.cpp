// Ellipsoid scene files (docs/FORMAT.md §1): every bad ellipsoid row is an InputError naming the file, the
// dataset and the row; body_rows builds the engine's shape rows in id order.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "io/inspect.hpp"
#include "io/scene_file.hpp"
#include "temp_dir.hpp"

namespace {

using cg::InputError;
using cg::RawType;
using cg::Scene;

class SceneShapes : public cg::test::TempDirTest {};

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

Scene mixed(int spheres = 3, int ellipsoids = 4) {
  Scene s;
  for (int i = 0; i < spheres; ++i) {
    s.sphere_position.push_back({1.0 * i, 0, 0});
    s.sphere_radius.push_back(0.5 + 0.1 * i);
  }
  for (int i = 0; i < ellipsoids; ++i) {
    s.ellipsoid_position.push_back({0, 2.0 * i, 1});
    s.ellipsoid_semi_axes.push_back({0.5, 0.8, 0.3 + 0.1 * i});
    const double a = 0.4 * i;
    s.ellipsoid_orientation.push_back({std::cos(a), 0.0, 0.0, std::sin(a)});
  }
  return s;
}

// The message of the InputError read_scene throws on `file` ("" and a failure if none).
std::string shape_error(const std::string& file) {
  try {
    cg::read_scene(file);
  } catch (const InputError& e) {
    return e.what();
  }
  ADD_FAILURE() << "no InputError";
  return "";
}

// The same for the scene `s` written to `file`.
std::string read_error(const std::string& file, const Scene& s) {
  cg::write_scene(file, s);
  return shape_error(file);
}

TEST_F(SceneShapes, NegativeSemiAxis) {
  Scene s = mixed();
  s.ellipsoid_semi_axes[2].y = -0.5;
  EXPECT_EQ(read_error(path("e.h5"), s),
            path("e.h5") + ": /ellipsoids/semi_axes row 2: semi-axis -0.5 is not > 0");
}

TEST_F(SceneShapes, ZeroSemiAxis) {
  Scene s = mixed();
  s.ellipsoid_semi_axes[0].x = 0;
  EXPECT_EQ(read_error(path("e.h5"), s),
            path("e.h5") + ": /ellipsoids/semi_axes row 0: semi-axis 0 is not > 0");
}

TEST_F(SceneShapes, NaNSemiAxis) {
  Scene s = mixed();
  s.ellipsoid_semi_axes[3].z = kNaN;
  EXPECT_EQ(read_error(path("e.h5"), s),
            path("e.h5") + ": /ellipsoids/semi_axes row 3: value nan is not finite");
}

TEST_F(SceneShapes, ZeroQuaternion) {
  Scene s = mixed();
  s.ellipsoid_orientation[1] = {0, 0, 0, 0};
  const std::string msg = read_error(path("e.h5"), s);
  EXPECT_NE(msg.find(path("e.h5") + ": /ellipsoids/orientation row 1: quaternion (0, 0, 0, 0) has norm 0"),
            std::string::npos)
      << msg;
}

TEST_F(SceneShapes, FarFromUnitQuaternion) {
  Scene s = mixed();
  s.ellipsoid_orientation[2] = {2, 0, 0, 0};
  const std::string msg = read_error(path("e.h5"), s);
  EXPECT_NE(
      msg.find(path("e.h5") + ": /ellipsoids/orientation row 2: quaternion (2, 0, 0, 0) has norm 2, not 1"),
      std::string::npos)
      << msg;
}

TEST_F(SceneShapes, QuaternionWithinTheEngineToleranceIsAccepted) {
  Scene s = mixed();
  s.ellipsoid_orientation[0] = {1 + 0.5 * cg::kQuaternionTolerance, 0, 0, 0};
  cg::write_scene(path("e.h5"), s);
  EXPECT_EQ(cg::read_scene(path("e.h5")).ellipsoid_count(), 4u);
}

TEST_F(SceneShapes, NaNPosition) {
  Scene s = mixed();
  s.ellipsoid_position[1].y = kNaN;
  EXPECT_EQ(read_error(path("e.h5"), s),
            path("e.h5") + ": /ellipsoids/position row 1: value nan is not finite");
}

TEST_F(SceneShapes, RowNumbersOfAPartialReadAreTheFile) {
  Scene s = mixed();
  s.ellipsoid_semi_axes[3].x = -1;
  cg::write_scene(path("e.h5"), s);
  try {
    cg::read_scene_rows(path("e.h5"), 5, 2);  // ellipsoids 2, 3
    ADD_FAILURE() << "no InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), path("e.h5") + ": /ellipsoids/semi_axes row 3: semi-axis -1 is not > 0");
  }
}

// Wrong shapes of the datasets: (M, 2) semi-axes, (M) orientation, rows that differ.
void write_raw_ellipsoids(const std::string& file, std::vector<std::uint64_t> position,
                          std::vector<std::uint64_t> semi, std::vector<std::uint64_t> orientation) {
  auto zeros = [](const std::vector<std::uint64_t>& dims) {
    std::uint64_t n = 1;
    for (std::uint64_t d : dims) n *= d;
    return std::vector<double>(n, 1.0);
  };
  cg::write_raw_dataset(file, "/ellipsoids/position", RawType::float64, position, zeros(position));
  cg::write_raw_dataset(file, "/ellipsoids/semi_axes", RawType::float64, semi, zeros(semi));
  cg::write_raw_dataset(file, "/ellipsoids/orientation", RawType::float64, orientation, zeros(orientation));
}

TEST_F(SceneShapes, SemiAxesWithTwoColumns) {
  write_raw_ellipsoids(path("e.h5"), {2, 3}, {2, 2}, {2, 4});
  const std::string msg = shape_error(path("e.h5"));
  EXPECT_NE(msg.find(path("e.h5")), std::string::npos) << msg;
  EXPECT_NE(msg.find("/ellipsoids/semi_axes"), std::string::npos) << msg;
}

TEST_F(SceneShapes, OrientationOneDimensional) {
  write_raw_ellipsoids(path("e.h5"), {2, 3}, {2, 3}, {2});
  const std::string msg = shape_error(path("e.h5"));
  EXPECT_NE(msg.find("/ellipsoids/orientation"), std::string::npos) << msg;
}

TEST_F(SceneShapes, RowCountsDiffer) {
  write_raw_ellipsoids(path("e.h5"), {3, 3}, {2, 3}, {3, 4});
  const std::string msg = shape_error(path("e.h5"));
  EXPECT_NE(msg.find("/ellipsoids/semi_axes"), std::string::npos) << msg;
}

TEST(BodyRows, SpheresThenEllipsoidsInIdOrder) {
  Scene s = mixed(3, 4);
  const Scene copy = s;
  cg::BodyRows rows = cg::body_rows(std::move(s), true);
  ASSERT_EQ(rows.size(), 7u);
  ASSERT_EQ(rows.shape.size(), 7u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(rows.shape[i], cg::Shape::sphere);
    EXPECT_EQ(rows.radius[i], copy.sphere_radius[i]);
    EXPECT_TRUE(rows.position[i] == copy.sphere_position[i]);
  }
  for (int j = 0; j < 4; ++j) {
    const auto& a = copy.ellipsoid_semi_axes[j];
    EXPECT_EQ(rows.shape[3 + j], cg::Shape::ellipsoid);
    EXPECT_EQ(rows.radius[3 + j], std::max({a.x, a.y, a.z}));
    EXPECT_TRUE(rows.semi_axes[3 + j] == a);
    EXPECT_EQ(rows.orientation[3 + j].w, copy.ellipsoid_orientation[j][0]);
    EXPECT_EQ(rows.orientation[3 + j].z, copy.ellipsoid_orientation[j][3]);
    EXPECT_TRUE(rows.position[3 + j] == copy.ellipsoid_position[j]);
  }
  cg::BodiesView view{rows.position, rows.radius, {}, {}, rows.shape, rows.semi_axes, rows.orientation};
  (void)cg::compute_bounds(view);
  EXPECT_EQ(cg::validate_shapes(view), 4u);
}

TEST(BodyRows, SphereOnlyRowsAreMovedWithoutShapes) {
  Scene s = mixed(5, 0);
  const double* data = s.sphere_radius.data();
  cg::BodyRows rows = cg::body_rows(std::move(s), false);
  EXPECT_EQ(rows.radius.data(), data);
  EXPECT_TRUE(rows.shape.empty());
}

}  // namespace
