// Unit tests of the HDF5 layer (src/io/), bad input: one test per kind of bad file, dataset or value, and
// damaged files, each checking the exception type and that the message names the file, the dataset and
// the row. Every test works in its own temporary directory (hdf5_io_helpers.hpp: Hdf5Io).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "hdf5_io_helpers.hpp"
#include "io/contact_file.hpp"
#include "io/inspect.hpp"
#include "io/scene_file.hpp"
#include "support/contacts_equal.hpp"
#include "support/paths.hpp"
#include "temp_dir.hpp"

namespace {

namespace fs = std::filesystem;
using cg::AttrValue;
using cg::Contacts;
using cg::InputError;
using cg::IoError;
using cg::RawType;
using cg::Scene;
using cg::Vec3;
using cg::test::error_of;
using cg::test::Hdf5Io;
using cg::test::mixed_scene;
using cg::test::sample_contacts;
using cg::test::sample_info;
using cg::test::sphere_scene;
using cg::test::write_raw_spheres;

// ---- bad input: contact files ------------------------------------------------------------------------

TEST_F(Hdf5Io, ReadContactsOfASceneFile) {
  cg::write_scene(path("s.h5"), sphere_scene(2));
  std::string msg = error_of<InputError>([&] { cg::read_contacts(path("s.h5")); });
  EXPECT_CONTAINS(msg, path("s.h5"));
  EXPECT_CONTAINS(msg, "precision");
}

TEST_F(Hdf5Io, ReadContactsWithMisshapedDataset) {
  cg::write_raw_attribute(path("c.h5"), "precision", AttrValue{std::string("fp64")});
  cg::write_raw_dataset(path("c.h5"), "/contacts/id_a", RawType::int64, {2}, std::vector<double>{0, 1});
  cg::write_raw_dataset(path("c.h5"), "/contacts/id_b", RawType::int64, {2}, std::vector<double>{1, 2});
  cg::write_raw_dataset(path("c.h5"), "/contacts/position_on_a", RawType::float64, {2, 2},
                        std::vector<double>(4));
  std::string msg = error_of<InputError>([&] { cg::read_contacts(path("c.h5")); });
  EXPECT_CONTAINS(msg, path("c.h5"));
  EXPECT_CONTAINS(msg, "/contacts/position_on_a");
  EXPECT_CONTAINS(msg, "(2, 2)");
}

// ---- bad input: the file ---------------------------------------------------------------------------

TEST_F(Hdf5Io, MissingFile) {
  std::string file = path("nope.h5");
  std::string msg = error_of<InputError>([&] { cg::read_scene(file); });
  EXPECT_CONTAINS(msg, file);
  EXPECT_CONTAINS(msg, "no such file");
  EXPECT_CONTAINS(error_of<InputError>([&] { cg::read_scene_shape(file); }), file);
  EXPECT_CONTAINS(error_of<InputError>([&] { cg::read_contacts(file); }), file);
}

TEST_F(Hdf5Io, DirectoryInsteadOfFile) {
  std::string msg = error_of<InputError>([&] { cg::read_scene(m_dir.string()); });
  EXPECT_CONTAINS(msg, m_dir.string());
}

TEST_F(Hdf5Io, NotAnHdf5File) {
  { std::ofstream(path("text.h5")) << "x y z r\n1 2 3 0.5\n"; }
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("text.h5")); });
  EXPECT_CONTAINS(msg, path("text.h5"));
  EXPECT_CONTAINS(msg, "not an HDF5 file");
}

TEST_F(Hdf5Io, EmptyFileIsNotHdf5) {
  { std::ofstream out(path("empty.h5")); }
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("empty.h5")); });
  EXPECT_CONTAINS(msg, path("empty.h5"));
}

TEST_F(Hdf5Io, TruncatedFile) {
  cg::write_scene(path("t.h5"), sphere_scene(1000));
  fs::resize_file(path("t.h5"), fs::file_size(path("t.h5")) / 2);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("t.h5")); });
  EXPECT_CONTAINS(msg, path("t.h5"));
  EXPECT_CONTAINS(error_of<InputError>([&] { cg::read_scene_shape(path("t.h5")); }), path("t.h5"));
}

TEST_F(Hdf5Io, TruncatedInsideTheHeader) {
  cg::write_scene(path("t.h5"), sphere_scene(1000));
  fs::resize_file(path("t.h5"), 40);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("t.h5")); });
  EXPECT_CONTAINS(msg, path("t.h5"));
}

TEST_F(Hdf5Io, TruncatedContactFile) {
  cg::write_contacts(path("c.h5"), sample_contacts<double>(1000, true), sample_info("fp64"));
  fs::resize_file(path("c.h5"), fs::file_size(path("c.h5")) - 1000);
  std::string msg = error_of<InputError>([&] { cg::read_contacts(path("c.h5")); });
  EXPECT_CONTAINS(msg, path("c.h5"));
}

// ---- bad input: datasets ----------------------------------------------------------------------------

TEST_F(Hdf5Io, MissingRadiusDataset) {
  cg::write_raw_dataset(path("s.h5"), "/spheres/position", RawType::float64, {1, 3},
                        std::vector<double>{0, 0, 0});
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(msg, path("s.h5"));
  EXPECT_CONTAINS(msg, "/spheres/radius");
  EXPECT_CONTAINS(msg, "missing");
}

TEST_F(Hdf5Io, MissingPositionDataset) {
  cg::write_raw_dataset(path("s.h5"), "/spheres/radius", RawType::float64, {1}, std::vector<double>{1});
  std::string msg = error_of<InputError>([&] { cg::read_scene_shape(path("s.h5")); });
  EXPECT_CONTAINS(msg, path("s.h5"));
  EXPECT_CONTAINS(msg, "/spheres/position");
}

TEST_F(Hdf5Io, MissingOrientationDataset) {
  cg::write_raw_dataset(path("e.h5"), "/ellipsoids/position", RawType::float64, {1, 3},
                        std::vector<double>(3));
  cg::write_raw_dataset(path("e.h5"), "/ellipsoids/semi_axes", RawType::float64, {1, 3},
                        std::vector<double>(3, 1.0));
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("e.h5")); });
  EXPECT_CONTAINS(msg, path("e.h5"));
  EXPECT_CONTAINS(msg, "/ellipsoids/orientation");
}

TEST_F(Hdf5Io, GroupThatIsADataset) {
  cg::write_raw_dataset(path("s.h5"), "/spheres", RawType::float64, {1}, std::vector<double>{1});
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(msg, path("s.h5"));
  EXPECT_CONTAINS(msg, "/spheres");
}

TEST_F(Hdf5Io, PositionWithTwoColumns) {
  cg::write_raw_dataset(path("s.h5"), "/spheres/position", RawType::float64, {5, 2}, std::vector<double>(10));
  cg::write_raw_dataset(path("s.h5"), "/spheres/radius", RawType::float64, {5}, std::vector<double>(5, 1.0));
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(msg, path("s.h5"));
  EXPECT_CONTAINS(msg, "/spheres/position");
  EXPECT_CONTAINS(msg, "(5, 2)");
}

TEST_F(Hdf5Io, PositionOfRankOne) {
  cg::write_raw_dataset(path("s.h5"), "/spheres/position", RawType::float64, {15}, std::vector<double>(15));
  cg::write_raw_dataset(path("s.h5"), "/spheres/radius", RawType::float64, {5}, std::vector<double>(5, 1.0));
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(msg, path("s.h5"));
  EXPECT_CONTAINS(msg, "/spheres/position");
  EXPECT_CONTAINS(msg, "(15)");
}

TEST_F(Hdf5Io, RadiusOfRankTwo) {
  cg::write_raw_dataset(path("s.h5"), "/spheres/position", RawType::float64, {5, 3}, std::vector<double>(15));
  cg::write_raw_dataset(path("s.h5"), "/spheres/radius", RawType::float64, {5, 1},
                        std::vector<double>(5, 1.0));
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(msg, "/spheres/radius");
  EXPECT_CONTAINS(msg, "(5, 1)");
}

TEST_F(Hdf5Io, OrientationWithThreeColumns) {
  cg::write_raw_dataset(path("e.h5"), "/ellipsoids/position", RawType::float64, {2, 3},
                        std::vector<double>(6));
  cg::write_raw_dataset(path("e.h5"), "/ellipsoids/semi_axes", RawType::float64, {2, 3},
                        std::vector<double>(6, 1.0));
  cg::write_raw_dataset(path("e.h5"), "/ellipsoids/orientation", RawType::float64, {2, 3},
                        std::vector<double>(6, 1.0));
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("e.h5")); });
  EXPECT_CONTAINS(msg, path("e.h5"));
  EXPECT_CONTAINS(msg, "/ellipsoids/orientation");
  EXPECT_CONTAINS(msg, "(2, 3)");
}

TEST_F(Hdf5Io, MismatchedRowCounts) {
  write_raw_spheres(path("s.h5"), std::vector<double>(30), std::vector<double>(9, 1.0));
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(msg, path("s.h5"));
  EXPECT_CONTAINS(msg, "/spheres/radius");
  EXPECT_CONTAINS(msg, "/spheres/position");
}

TEST_F(Hdf5Io, Int32PositionIsRejected) {
  write_raw_spheres(path("s.h5"), std::vector<double>(6), std::vector<double>(2, 1.0), RawType::int32);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(msg, path("s.h5"));
  EXPECT_CONTAINS(msg, "/spheres/position");
  EXPECT_CONTAINS(msg, "32-bit integer");
}

TEST_F(Hdf5Io, Int64RadiusIsRejected) {
  cg::write_raw_dataset(path("s.h5"), "/spheres/position", RawType::float64, {2, 3}, std::vector<double>(6));
  cg::write_raw_dataset(path("s.h5"), "/spheres/radius", RawType::int64, {2}, std::vector<double>(2, 1.0));
  std::string msg = error_of<InputError>([&] { cg::read_scene_shape(path("s.h5")); });
  EXPECT_CONTAINS(msg, "/spheres/radius");
  EXPECT_CONTAINS(msg, "64-bit integer");
}

TEST_F(Hdf5Io, ZeroBodies) {
  write_raw_spheres(path("s.h5"), {}, {});
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(msg, path("s.h5"));
  EXPECT_CONTAINS(msg, "scene has no bodies");
  EXPECT_CONTAINS(error_of<InputError>([&] { cg::read_scene_shape(path("s.h5")); }), "scene has no bodies");
}

TEST_F(Hdf5Io, FileWithoutGroupsHasNoBodies) {
  cg::write_raw_attribute(path("s.h5"), "note", AttrValue{std::string("nothing here")});
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(
      msg, path("s.h5") + ": scene has no bodies: no /spheres or /ellipsoids group; the file holds nothing");
}

// A user's first file, h5py style, with the datasets at the root: the message names what it found and
// where they belong.
TEST_F(Hdf5Io, DatasetsAtTheRootAreNamed) {
  cg::write_raw_dataset(path("s.h5"), "/position", RawType::float64, {4, 3}, std::vector<double>(12, 1.0));
  cg::write_raw_dataset(path("s.h5"), "/radius", RawType::float64, {4}, std::vector<double>(4, 0.5));
  for (const std::string& msg : {error_of<InputError>([&] { cg::read_scene(path("s.h5")); }),
                                 error_of<InputError>([&] { cg::read_scene_shape(path("s.h5")); })}) {
    EXPECT_CONTAINS(msg, path("s.h5") + ": scene has no bodies");
    EXPECT_CONTAINS(msg, "/position (4, 3), /radius (4)");
    EXPECT_CONTAINS(msg, "/spheres/position (N, 3) and /spheres/radius (N)");
  }
}

TEST_F(Hdf5Io, MisnamedDatasetInTheGroupIsNamed) {
  cg::write_raw_dataset(path("s.h5"), "/spheres/positions", RawType::float64, {4, 3},
                        std::vector<double>(12));
  cg::write_raw_dataset(path("s.h5"), "/spheres/radius", RawType::float64, {4}, std::vector<double>(4, 0.5));
  const std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(
      msg,
      "/spheres/position: missing dataset (/spheres holds /spheres/positions (4, 3), /spheres/radius (4))");
}

// Orientations stored scalar last (SciPy's Rotation.as_quat), said so by the root attribute
// quaternion_order = "xyzw": read as (w, x, y, z); the attribute is consumed (a scene written back
// holds (w, x, y, z) and no attribute). Any other value is refused, naming it.
TEST_F(Hdf5Io, QuaternionOrderXyzwIsReadAsWxyz) {
  Scene s = mixed_scene();
  Scene stored = s;
  for (auto& q : stored.ellipsoid_orientation) q = {q[1], q[2], q[3], q[0]};
  stored.attributes["quaternion_order"] = std::string("xyzw");
  cg::write_scene(path("xyzw.h5"), stored);
  const Scene read = cg::read_scene(path("xyzw.h5"));
  ASSERT_EQ(read.ellipsoid_count(), s.ellipsoid_count());
  for (std::size_t i = 0; i < s.ellipsoid_count(); ++i)
    EXPECT_EQ(read.ellipsoid_orientation[i], s.ellipsoid_orientation[i]) << "ellipsoid " << i;
  EXPECT_EQ(read.attributes.count("quaternion_order"), 0u);
  const Scene rows = cg::read_scene_rows(path("xyzw.h5"), 1, s.size() - 1);  // the ranks' reader too
  EXPECT_EQ(rows.ellipsoid_orientation.back(), s.ellipsoid_orientation.back());

  stored.attributes["quaternion_order"] = std::string("wxyz");
  stored.ellipsoid_orientation = s.ellipsoid_orientation;
  cg::write_scene(path("wxyz.h5"), stored);
  EXPECT_EQ(cg::read_scene(path("wxyz.h5")).ellipsoid_orientation, s.ellipsoid_orientation);

  stored.attributes["quaternion_order"] = std::string("zyxw");
  cg::write_scene(path("bad.h5"), stored);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("bad.h5")); });
  EXPECT_CONTAINS(msg, "root attribute quaternion_order = \"zyxw\"");
  EXPECT_CONTAINS(msg, "\"xyzw\"");
  stored.attributes["quaternion_order"] = std::int64_t{4};
  cg::write_scene(path("number.h5"), stored);
  msg = error_of<InputError>([&] { cg::read_scene(path("number.h5")); });
  EXPECT_CONTAINS(msg, "root attribute quaternion_order is not a string");
}

// An output directory that does not exist: the message names it, not the temporary name nor HDF5's
// internal flags, and nothing is left behind.
TEST_F(Hdf5Io, MissingOutputDirectoryIsNamed) {
  const std::string dir = path("no_such_dir");
  for (const std::string& msg :
       {error_of<IoError>([&] { cg::write_scene(dir + "/s.h5", mixed_scene()); }), error_of<IoError>([&] {
          Contacts<double> c;
          cg::RunInfo info;
          info.precision = "fp64";
          cg::write_contacts(dir + "/c.h5", c, info);
        })}) {
    EXPECT_CONTAINS(msg, "cannot write into the directory " + dir + ": it does not exist");
    EXPECT_EQ(msg.find(".tmp."), std::string::npos) << msg;
    EXPECT_EQ(msg.find("flags"), std::string::npos) << msg;
  }
  ASSERT_TRUE(fs::create_directory(dir));
  { std::ofstream(dir + "/file") << "x"; }
  const std::string msg = error_of<IoError>([&] { cg::write_scene(dir + "/file/s.h5", mixed_scene()); });
  EXPECT_CONTAINS(msg, "cannot write into the directory " + dir + "/file: it is not a directory");
}

TEST_F(Hdf5Io, EmptySceneWrittenIsRejectedOnRead) {
  cg::write_scene(path("s.h5"), Scene{});
  EXPECT_CONTAINS(error_of<InputError>([&] { cg::read_scene(path("s.h5")); }), "scene has no bodies");
}

// ---- bad input: values ----------------------------------------------------------------------------

TEST_F(Hdf5Io, NaNPosition) {
  Scene s = sphere_scene(10);
  s.sphere_position[3].y = std::numeric_limits<double>::quiet_NaN();
  cg::write_scene(path("s.h5"), s);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_EQ(msg, path("s.h5") + ": /spheres/position row 3: value nan is not finite");
}

TEST_F(Hdf5Io, InfRadius) {
  Scene s = sphere_scene(10);
  s.sphere_radius[8] = std::numeric_limits<double>::infinity();
  cg::write_scene(path("s.h5"), s);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_EQ(msg, path("s.h5") + ": /spheres/radius row 8: value inf is not finite");
}

TEST_F(Hdf5Io, NegativeInfPositionInFloat32) {
  std::vector<double> position(12, 1.0);
  position[7] = -std::numeric_limits<double>::infinity();  // row 2
  write_raw_spheres(path("f.h5"), position, std::vector<double>(4, 1.0), RawType::float32);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("f.h5")); });
  EXPECT_EQ(msg, path("f.h5") + ": /spheres/position row 2: value -inf is not finite");
}

TEST_F(Hdf5Io, NegativeRadius) {
  Scene s = sphere_scene(20);
  s.sphere_radius[17] = -1;
  cg::write_scene(path("s.h5"), s);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_EQ(msg, path("s.h5") + ": /spheres/radius row 17: radius -1 is not > 0");
}

TEST_F(Hdf5Io, ZeroRadius) {
  Scene s = sphere_scene(5);
  s.sphere_radius[0] = 0;
  cg::write_scene(path("s.h5"), s);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_EQ(msg, path("s.h5") + ": /spheres/radius row 0: radius 0 is not > 0");
}

TEST_F(Hdf5Io, RadiusAboveRadiusHigh) {
  Scene s = sphere_scene(10);
  s.radius_low = 0.5;
  s.radius_high = 1.0;
  s.sphere_radius[6] = 1.25;
  cg::write_scene(path("s.h5"), s);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_EQ(msg, path("s.h5") +
                     ": /spheres/radius row 6: radius 1.25 is outside [radius_low, radius_high] = [0.5, 1]");
}

TEST_F(Hdf5Io, RadiusBelowRadiusLow) {
  Scene s = sphere_scene(10);
  s.radius_low = 0.5;
  s.sphere_radius[4] = 0.25;
  cg::write_scene(path("s.h5"), s);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(msg, path("s.h5"));
  EXPECT_CONTAINS(msg, "/spheres/radius row 4");
  EXPECT_CONTAINS(msg, "radius 0.25 is outside");
}

TEST_F(Hdf5Io, RadiusEqualToTheBoundsIsAccepted) {
  Scene s = sphere_scene(2);
  s.sphere_radius = {0.5, 1.0};
  s.radius_low = 0.5;
  s.radius_high = 1.0;
  cg::write_scene(path("s.h5"), s);
  EXPECT_EQ(cg::read_scene(path("s.h5")).size(), 2u);
}

TEST_F(Hdf5Io, EllipsoidBoundingRadiusOutsideBounds) {
  Scene s = mixed_scene();
  s.ellipsoid_semi_axes[2] = {0.5, 2.5, 0.5};  // bounding radius 2.5 > radius_high 2
  cg::write_scene(path("m.h5"), s);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("m.h5")); });
  EXPECT_EQ(msg, path("m.h5") +
                     ": /ellipsoids/semi_axes row 2: bounding radius 2.5 is outside [radius_low, "
                     "radius_high] = [0.25, 2]");
}

TEST_F(Hdf5Io, NonPositiveSemiAxis) {
  Scene s = mixed_scene();
  s.ellipsoid_semi_axes[1].z = 0;
  cg::write_scene(path("m.h5"), s);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("m.h5")); });
  EXPECT_EQ(msg, path("m.h5") + ": /ellipsoids/semi_axes row 1: semi-axis 0 is not > 0");
}

TEST_F(Hdf5Io, NonUnitQuaternion) {
  Scene s = mixed_scene();
  s.ellipsoid_orientation[3] = {1, 0, 0, 1e-2};  // norm 1.00005
  cg::write_scene(path("m.h5"), s);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("m.h5")); });
  EXPECT_CONTAINS(msg, path("m.h5") + ": /ellipsoids/orientation row 3: quaternion (1, 0, 0, 0.01)");
  EXPECT_CONTAINS(msg, "not 1");
}

TEST_F(Hdf5Io, QuaternionWithinToleranceIsAccepted) {
  Scene s = mixed_scene();
  s.ellipsoid_orientation[0] = {1 + 5e-7, 0, 0, 0};
  cg::write_scene(path("m.h5"), s);
  EXPECT_EQ(cg::read_scene(path("m.h5")).ellipsoid_count(), 4u);
}

TEST_F(Hdf5Io, NaNQuaternion) {
  Scene s = mixed_scene();
  s.ellipsoid_orientation[1][2] = std::numeric_limits<double>::quiet_NaN();
  cg::write_scene(path("m.h5"), s);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("m.h5")); });
  EXPECT_EQ(msg, path("m.h5") + ": /ellipsoids/orientation row 1: value nan is not finite");
}

TEST_F(Hdf5Io, FirstBadRowIsReported) {
  Scene s = sphere_scene(10);
  s.sphere_position[5].x = std::numeric_limits<double>::quiet_NaN();
  s.sphere_radius[3] = -4;
  s.sphere_radius[7] = 0;
  cg::write_scene(path("s.h5"), s);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_EQ(msg, path("s.h5") + ": /spheres/radius row 3: radius -4 is not > 0");
}

TEST_F(Hdf5Io, BadRowBeyondTheFirstReadChunk) {
  const std::size_t n = (std::size_t(1) << 20) + 5000;
  Scene s;
  s.sphere_position.assign(n, Vec3<double>{1, 2, 3});
  s.sphere_radius.assign(n, 0.5);
  s.sphere_radius[n - 7] = -0.5;
  cg::write_scene(path("big.h5"), s);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("big.h5")); });
  EXPECT_EQ(msg,
            path("big.h5") + ": /spheres/radius row " + std::to_string(n - 7) + ": radius -0.5 is not > 0");
}

TEST_F(Hdf5Io, StringRadiusBoundIsRejected) {
  write_raw_spheres(path("s.h5"), {0, 0, 0}, {1});
  cg::write_raw_attribute(path("s.h5"), "radius_high", AttrValue{std::string("big")});
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(msg, path("s.h5"));
  EXPECT_CONTAINS(msg, "radius_high");
}

TEST_F(Hdf5Io, InvertedRadiusBoundsAreRejected) {
  write_raw_spheres(path("s.h5"), {0, 0, 0}, {1});
  cg::write_raw_attribute(path("s.h5"), "radius_low", AttrValue{2.0});
  cg::write_raw_attribute(path("s.h5"), "radius_high", AttrValue{1.0});
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(msg, "radius_low = 2 > radius_high = 1");
}

// ---- damaged files (issue #21) ----------------------------------------------------------------------

namespace damaged {

std::vector<char> bytes_of(const std::string& file) {
  std::ifstream in(file, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
void put(const std::string& file, const std::vector<char>& b) {
  std::ofstream(file, std::ios::binary | std::ios::trunc)
      .write(b.data(), static_cast<std::streamsize>(b.size()));
}
// Sets the size field of the first object of the file's global heap collection ("GCOL"): the heap
// that holds variable-length strings. HDF5 1.10.8 would copy that many bytes into the string.
void corrupt_first_heap_object(const std::string& file) {
  std::vector<char> b = bytes_of(file);
  const std::string gcol = "GCOL";
  auto it = std::search(b.begin(), b.end(), gcol.begin(), gcol.end());
  ASSERT_NE(it, b.end());
  const std::size_t object = static_cast<std::size_t>(it - b.begin()) + 16;  // after the collection header
  for (int k = 0; k < 8; ++k) b[object + 8 + k] = k == 3 ? 0x7f : 0;         // size 2^31
  put(file, b);
}

}  // namespace damaged

TEST_F(Hdf5Io, DamagedStringHeapLeavesStringAttributesOutButReadsTheScene) {
  const Scene s = mixed_scene();
  cg::write_scene(path("s.h5"), s);
  damaged::corrupt_first_heap_object(path("s.h5"));
  const Scene back = cg::read_scene(path("s.h5"));
  EXPECT_EQ(back.size(), s.size());
  EXPECT_EQ(back.radius_high, 2.0);
  EXPECT_EQ(back.attributes.count("generator"), 0u);  // its heap object no longer checks out
  EXPECT_EQ(std::get<std::int64_t>(back.attributes.at("seed")), -5);
}

TEST_F(Hdf5Io, DamagedStringHeapInAContactFileTakesThePrecisionFromTheDatasets) {
  cg::write_contacts(path("c.h5"), sample_contacts<float>(5, false), sample_info("fp32"));
  damaged::corrupt_first_heap_object(path("c.h5"));
  const cg::ContactFile back = cg::read_contacts(path("c.h5"));
  EXPECT_EQ(back.precision, "fp32");
  EXPECT_EQ(back.contacts.size(), 5u);
}

TEST_F(Hdf5Io, DatasetLargerThanTheFileIsRejectedBeforeReading) {
  cg::write_scene(path("s.h5"), sphere_scene(1000));
  // Cut into the last dataset's rows and make the superblock agree (its end-of-file address, bytes
  // 40…47 of a version 0 superblock), so that HDF5 opens the file and only the rows are missing.
  const std::uint64_t size = fs::file_size(path("s.h5")) - 4000;
  fs::resize_file(path("s.h5"), size);
  std::vector<char> b = damaged::bytes_of(path("s.h5"));
  ASSERT_EQ(b[8], 0);  // superblock version 0
  for (int k = 0; k < 8; ++k) b[40 + k] = static_cast<char>((size >> (8 * k)) & 0xff);
  damaged::put(path("s.h5"), b);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("s.h5")); });
  EXPECT_CONTAINS(msg, path("s.h5"));
  EXPECT_CONTAINS(msg, "/spheres/");
}

// The two findings of libFuzzer run 6 (BENCHMARKS §7): refused from the file's bytes before HDF5
// reads what crashed or hung it, with a message naming the file and the object.
TEST_F(Hdf5Io, SharedMessageWithoutTableAndLoopingHeapFreeListAreInputErrors) {
  const fs::path dir = fs::path(cg::test::source_dir()) / "tests/data/damaged";
  const std::string shared = (dir / "shared_message_without_table_segv.h5").string();
  std::string msg = error_of<InputError>([&] { cg::inspect_dataset(shared, "/contacts/id_a"); });
  EXPECT_CONTAINS(msg, shared);
  EXPECT_CONTAINS(msg, "/contacts/id_a: damaged: its header message 5 is stored in a shared-message table");
  msg = error_of<InputError>([&] { cg::read_contacts(shared); });
  EXPECT_CONTAINS(msg, "/contacts/id_a: damaged");
  const std::string root = (dir / "root_attribute_shared_without_table_segv.h5").string();
  msg = error_of<InputError>([&] { cg::read_contacts(root); });
  EXPECT_CONTAINS(msg, root);
  EXPECT_CONTAINS(msg, "the root group's header is damaged");
  const std::string loop = (dir / "hdf5_memory_growth_hang.h5").string();
  for (const std::string& m :
       {error_of<InputError>([&] { cg::read_scene(loop); }),
        error_of<InputError>([&] { cg::read_contacts(loop); }),
        error_of<InputError>([&] { cg::read_dataset_bytes(loop, "/contacts/distance"); })}) {
    EXPECT_CONTAINS(m, loop);
    EXPECT_CONTAINS(m, "the group / is damaged: its local heap at 680 has a damaged free list");
  }
}

// Every file of tests/data/damaged crashed or hung a reader once (libFuzzer, mutation test); each
// is now an InputError (or, for a file whose damage does not touch what a reader uses, a success).
TEST_F(Hdf5Io, DamagedRegressionFilesAreInputErrors) {
  const fs::path dir = fs::path(cg::test::source_dir()) / "tests/data/damaged";
  int files = 0;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().extension() != ".h5") continue;
    ++files;
    const std::string file = e.path().string();
    auto clean = [&](auto&& read) {
      try {
        read();
      } catch (const InputError& error) {
        EXPECT_CONTAINS(std::string(error.what()), file);
      }
    };
    clean([&] { cg::read_scene(file); });
    clean([&] { cg::read_scene_shape(file); });
    clean([&] { cg::read_contacts(file); });
    for (const cg::ContactField& field : cg::kContactFields) {
      const std::string ds = field.path;
      clean([&] {
        if (cg::inspect_dataset(file, ds)) cg::read_dataset_bytes(file, ds);
      });
    }
  }
  EXPECT_GT(files, 0);
}

}  // namespace
