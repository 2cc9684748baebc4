// Unit tests of the HDF5 layer (src/io/): scene and contact round trips. Every test works in its own
// temporary directory, removed afterwards. The phased contact writer is test_hdf5_phased.cpp; one test
// per kind of bad input (the exception type, and a message that names the file, the dataset and the
// row) test_hdf5_bad_input.cpp; their shared pieces hdf5_io_helpers.hpp.
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

std::vector<unsigned char> file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void expect_same_scene(const Scene& a, const Scene& b) {
  ASSERT_EQ(a.sphere_count(), b.sphere_count());
  ASSERT_EQ(a.ellipsoid_count(), b.ellipsoid_count());
  for (std::size_t i = 0; i < a.sphere_count(); ++i) {
    EXPECT_TRUE(a.sphere_position[i] == b.sphere_position[i]) << "sphere " << i;
    EXPECT_EQ(a.sphere_radius[i], b.sphere_radius[i]) << "sphere " << i;
  }
  for (std::size_t i = 0; i < a.ellipsoid_count(); ++i) {
    EXPECT_TRUE(a.ellipsoid_position[i] == b.ellipsoid_position[i]) << "ellipsoid " << i;
    EXPECT_TRUE(a.ellipsoid_semi_axes[i] == b.ellipsoid_semi_axes[i]) << "ellipsoid " << i;
    EXPECT_EQ(a.ellipsoid_orientation[i], b.ellipsoid_orientation[i]) << "ellipsoid " << i;
  }
  EXPECT_EQ(a.radius_low, b.radius_low);
  EXPECT_EQ(a.radius_high, b.radius_high);
  EXPECT_EQ(a.attributes, b.attributes);
}

template <class Real>
void contacts_round_trip(const std::string& file, std::size_t k, bool full) {
  const bool fp32 = std::is_same_v<Real, float>;
  Contacts<Real> c = sample_contacts<Real>(k, full);
  cg::write_contacts(file, c, sample_info(fp32 ? "fp32" : "fp64"));
  cg::ContactFile back = cg::read_contacts(file);
  EXPECT_EQ(back.precision, fp32 ? "fp32" : "fp64");
  EXPECT_EQ(back.contacts.full, full);
  ASSERT_EQ(back.contacts.size(), k);
  EXPECT_EQ(cg::test::compare_contacts(c, back.contacts), "identical");
  const std::string real = fp32 ? "float32" : "float64";
  const std::uint64_t rows = k;
  auto expect_dataset = [&](const std::string& name, const std::string& type,
                            std::vector<std::uint64_t> dims) {
    auto info = cg::inspect_dataset(file, name);
    ASSERT_TRUE(info.has_value()) << name;
    EXPECT_EQ(info->type, type) << name;
    EXPECT_EQ(info->dims, dims) << name;
  };
  expect_dataset("/contacts/id_a", "int64", {rows});
  expect_dataset("/contacts/id_b", "int64", {rows});
  expect_dataset("/contacts/position_on_a", real, {rows, 3});
  expect_dataset("/contacts/position_on_b", real, {rows, 3});
  expect_dataset("/contacts/normal_on_b", real, {rows, 3});
  expect_dataset("/contacts/distance", real, {rows});
  for (const char* name : {"/contacts/local_point_a", "/contacts/local_point_b",
                           "/contacts/lateral_friction_dir1", "/contacts/lateral_friction_dir2"}) {
    if (full)
      expect_dataset(name, real, {rows, 3});
    else
      EXPECT_FALSE(cg::inspect_dataset(file, name).has_value()) << name;
  }
}

// ---- round trips ------------------------------------------------------------------------------------

TEST_F(Hdf5Io, SceneRoundTripSpheres) {
  Scene s = sphere_scene(100);
  cg::write_scene(path("s.h5"), s);
  Scene back = cg::read_scene(path("s.h5"));
  expect_same_scene(s, back);
  EXPECT_EQ(back.source, path("s.h5"));
  EXPECT_EQ(entries(), std::vector<std::string>{"s.h5"});  // no temporary left
  auto info = cg::inspect_dataset(path("s.h5"), "/spheres/position");
  ASSERT_TRUE(info.has_value());
  EXPECT_EQ(info->type, "float64");
  EXPECT_EQ(info->dims, (std::vector<std::uint64_t>{100, 3}));
}

// Large float64 scenes are read straight from the file in 4 MiB blocks on all threads: every row
// and every partial range come back bit for bit, like through HDF5 (the float32 tests take that path).
TEST_F(Hdf5Io, LargeSceneReadsInParallelBlocks) {
  Scene s = sphere_scene(400000);  // 9.6 MB of positions: three blocks and a tail
  cg::write_scene(path("big.h5"), s);
  expect_same_scene(s, cg::read_scene(path("big.h5")));
  const std::size_t first = 123457, count = 250001;
  Scene part = cg::read_scene_rows(path("big.h5"), first, count);
  ASSERT_EQ(part.sphere_count(), count);
  EXPECT_EQ(std::memcmp(part.sphere_position.data(), s.sphere_position.data() + first, count * 24), 0);
  EXPECT_EQ(std::memcmp(part.sphere_radius.data(), s.sphere_radius.data() + first, count * 8), 0);
}

// Large ellipsoid scenes take the same parallel path (blocks read on all threads, rows checked in
// parallel up to the first bad one): rows, partial ranges and the xyzw order come back exactly, and of
// several bad rows far apart the message names the first, whatever the threads.
TEST_F(Hdf5Io, LargeEllipsoidSceneReadsInParallelAndNamesTheFirstBadRow) {
  constexpr std::size_t n = 300000;  // above the parallel checks' threshold, several 4 MiB blocks
  Scene s;
  for (std::size_t i = 0; i < n; ++i) {
    const double a = 1e-5 * double(i);
    s.ellipsoid_position.push_back({0.5 * double(i), -1.0, 2e3 + 1e-3 * double(i)});
    s.ellipsoid_semi_axes.push_back({0.5, 0.75, 1.0 + 1e-6 * double(i % 1000)});
    s.ellipsoid_orientation.push_back({std::cos(a), 0.0, std::sin(a), 0.0});
  }
  Scene stored = s;
  for (auto& q : stored.ellipsoid_orientation) q = {q[1], q[2], q[3], q[0]};
  stored.attributes["quaternion_order"] = std::string("xyzw");
  cg::write_scene(path("big.h5"), stored);
  s.attributes.clear();
  expect_same_scene(s, cg::read_scene(path("big.h5")));
  const std::size_t first = 70001, count = 200003;
  const Scene part = cg::read_scene_rows(path("big.h5"), first, count);
  ASSERT_EQ(part.ellipsoid_count(), count);
  EXPECT_EQ(
      std::memcmp(part.ellipsoid_orientation.data(), s.ellipsoid_orientation.data() + first, count * 32), 0);
  EXPECT_EQ(std::memcmp(part.ellipsoid_semi_axes.data(), s.ellipsoid_semi_axes.data() + first, count * 24),
            0);

  Scene bad = s;
  bad.ellipsoid_orientation[250123] = {2, 0, 0, 0};
  bad.ellipsoid_semi_axes[180017].y = -0.5;
  bad.ellipsoid_position[299990].z = std::numeric_limits<double>::quiet_NaN();
  cg::write_scene(path("bad.h5"), bad);
  std::string msg = error_of<InputError>([&] { cg::read_scene(path("bad.h5")); });
  EXPECT_EQ(msg, path("bad.h5") + ": /ellipsoids/semi_axes row 180017: semi-axis -0.5 is not > 0");
  msg = error_of<InputError>([&] { cg::read_scene_rows(path("bad.h5"), 190000, 100000); });
  EXPECT_CONTAINS(msg, "/ellipsoids/orientation row 250123: quaternion (2, 0, 0, 0) has norm 2");
}

TEST_F(Hdf5Io, SceneRoundTripEllipsoidsBoundsAndAttributes) {
  Scene s = mixed_scene();
  cg::write_scene(path("m.h5"), s);
  Scene back = cg::read_scene(path("m.h5"));
  expect_same_scene(s, back);
  EXPECT_EQ(back.attributes.count("radius_low"), 0u);
  EXPECT_EQ(std::get<std::string>(back.attributes.at("generator")), "test");
  EXPECT_EQ(std::get<std::int64_t>(back.attributes.at("seed")), -5);
  EXPECT_EQ(std::get<double>(back.attributes.at("box_edge")), 12.5);
}

TEST_F(Hdf5Io, SceneWithoutBoundsHasNoBounds) {
  cg::write_scene(path("s.h5"), sphere_scene(3));
  Scene back = cg::read_scene(path("s.h5"));
  EXPECT_FALSE(back.radius_low.has_value());
  EXPECT_FALSE(back.radius_high.has_value());
  EXPECT_TRUE(back.attributes.empty());
}

TEST_F(Hdf5Io, EllipsoidOnlyScene) {
  Scene s = mixed_scene();
  s.sphere_position.clear();
  s.sphere_radius.clear();
  cg::write_scene(path("e.h5"), s);
  Scene back = cg::read_scene(path("e.h5"));
  expect_same_scene(s, back);
  EXPECT_FALSE(cg::inspect_dataset(path("e.h5"), "/spheres/position").has_value());
}

TEST_F(Hdf5Io, SceneShape) {
  cg::write_scene(path("m.h5"), mixed_scene());
  cg::SceneShape shape = cg::read_scene_shape(path("m.h5"));
  EXPECT_EQ(shape.spheres, 6u);
  EXPECT_EQ(shape.ellipsoids, 4u);
}

TEST_F(Hdf5Io, SceneRowsUseGlobalBodyIds) {
  Scene s = mixed_scene();
  cg::write_scene(path("m.h5"), s);
  Scene part = cg::read_scene_rows(path("m.h5"), 4, 4);  // spheres 4, 5 and ellipsoids 0, 1
  ASSERT_EQ(part.sphere_count(), 2u);
  ASSERT_EQ(part.ellipsoid_count(), 2u);
  EXPECT_TRUE(part.sphere_position[0] == s.sphere_position[4]);
  EXPECT_EQ(part.sphere_radius[1], s.sphere_radius[5]);
  EXPECT_TRUE(part.ellipsoid_semi_axes[1] == s.ellipsoid_semi_axes[1]);
  EXPECT_EQ(part.radius_high, 2.0);
  EXPECT_EQ(std::get<std::string>(part.attributes.at("generator")), "test");

  Scene spheres = cg::read_scene_rows(path("m.h5"), 1, 2);
  ASSERT_EQ(spheres.sphere_count(), 2u);
  EXPECT_EQ(spheres.ellipsoid_count(), 0u);
  EXPECT_EQ(spheres.sphere_radius[0], s.sphere_radius[1]);

  Scene ellipsoids = cg::read_scene_rows(path("m.h5"), 9, 1);
  EXPECT_EQ(ellipsoids.sphere_count(), 0u);
  ASSERT_EQ(ellipsoids.ellipsoid_count(), 1u);
  EXPECT_EQ(ellipsoids.ellipsoid_orientation[0], s.ellipsoid_orientation[3]);

  EXPECT_EQ(cg::read_scene_rows(path("m.h5"), 10, 0).size(), 0u);
}

TEST_F(Hdf5Io, SceneRowsOutOfRangeIsUsageError) {
  cg::write_scene(path("m.h5"), mixed_scene());
  std::string msg = error_of<cg::UsageError>([&] { cg::read_scene_rows(path("m.h5"), 8, 3); });
  EXPECT_CONTAINS(msg, path("m.h5"));
}

TEST_F(Hdf5Io, SceneRowsNameTheFileRow) {
  Scene s = sphere_scene(20);
  s.sphere_radius[13] = -2;
  cg::write_scene(path("s.h5"), s);
  EXPECT_EQ(cg::read_scene_rows(path("s.h5"), 0, 13).size(), 13u);  // the bad row is not read
  std::string msg = error_of<InputError>([&] { cg::read_scene_rows(path("s.h5"), 10, 5); });
  EXPECT_EQ(msg, path("s.h5") + ": /spheres/radius row 13: radius -2 is not > 0");
}

TEST_F(Hdf5Io, Float32SceneIsConvertedToDouble) {
  std::vector<double> position{0.1, 0.2, 0.3, 1e7 + 0.5, -2.25, 3.0};
  std::vector<double> radius{0.7, 0.9};
  write_raw_spheres(path("f.h5"), position, radius, RawType::float32);
  EXPECT_EQ(cg::inspect_dataset(path("f.h5"), "/spheres/position")->type, "float32");
  Scene s = cg::read_scene(path("f.h5"));
  ASSERT_EQ(s.sphere_count(), 2u);
  EXPECT_EQ(s.sphere_position[0].x, double(0.1f));
  EXPECT_EQ(s.sphere_position[1].x, double(float(1e7 + 0.5)));
  EXPECT_EQ(s.sphere_position[1].y, -2.25);
  EXPECT_EQ(s.sphere_radius[0], double(0.7f));
}

TEST_F(Hdf5Io, MixedFloat32AndFloat64Datasets) {
  cg::write_raw_dataset(path("f.h5"), "/spheres/position", RawType::float64, {1, 3},
                        std::vector<double>{0.1, 0, 0});
  cg::write_raw_dataset(path("f.h5"), "/spheres/radius", RawType::float32, {1}, std::vector<double>{0.1});
  Scene s = cg::read_scene(path("f.h5"));
  EXPECT_EQ(s.sphere_position[0].x, 0.1);
  EXPECT_EQ(s.sphere_radius[0], double(0.1f));
}

TEST_F(Hdf5Io, IntegerBoundAttributesAreAccepted) {
  write_raw_spheres(path("s.h5"), {0, 0, 0}, {1.5});
  cg::write_raw_attribute(path("s.h5"), "radius_low", AttrValue{std::int64_t{1}});
  cg::write_raw_attribute(path("s.h5"), "radius_high", AttrValue{std::int64_t{2}});
  Scene s = cg::read_scene(path("s.h5"));
  EXPECT_EQ(s.radius_low, 1.0);
  EXPECT_EQ(s.radius_high, 2.0);
}

TEST_F(Hdf5Io, ContactsRoundTripFp64Basic) { contacts_round_trip<double>(path("c.h5"), 17, false); }
TEST_F(Hdf5Io, ContactsRoundTripFp32Basic) { contacts_round_trip<float>(path("c.h5"), 17, false); }
TEST_F(Hdf5Io, ContactsRoundTripFp64Full) { contacts_round_trip<double>(path("c.h5"), 17, true); }
TEST_F(Hdf5Io, ContactsRoundTripFp32Full) { contacts_round_trip<float>(path("c.h5"), 17, true); }
TEST_F(Hdf5Io, ContactsEmptyFp64Basic) { contacts_round_trip<double>(path("c.h5"), 0, false); }
TEST_F(Hdf5Io, ContactsEmptyFp32Basic) { contacts_round_trip<float>(path("c.h5"), 0, false); }
TEST_F(Hdf5Io, ContactsEmptyFp64Full) { contacts_round_trip<double>(path("c.h5"), 0, true); }
TEST_F(Hdf5Io, ContactsEmptyFp32Full) { contacts_round_trip<float>(path("c.h5"), 0, true); }

TEST_F(Hdf5Io, ContactFileRootAttributes) {
  cg::RunInfo info = sample_info("fp64");
  info.times.push_back({"sort", 0.5});  // a stage named twice adds up
  cg::write_contacts(path("c.h5"), sample_contacts<double>(5, false), info);
  cg::ContactFile back = cg::read_contacts(path("c.h5"));
  const cg::Attributes& a = back.attributes;
  EXPECT_EQ(std::get<std::string>(a.at("precision")), "fp64");
  EXPECT_EQ(std::get<std::string>(a.at("backend")), "cpu");
  EXPECT_EQ(std::get<std::int64_t>(a.at("ranks")), 3);
  EXPECT_EQ(std::get<std::int64_t>(a.at("bodies")), 1234);
  EXPECT_EQ(std::get<std::int64_t>(a.at("contacts")), 5);
  EXPECT_EQ(std::get<double>(a.at("cell_size")), 2.5);
  EXPECT_EQ(std::get<std::string>(a.at("software_version")), CONTACTGRID_VERSION);
  EXPECT_EQ(std::get<std::string>(a.at("input")), "scene.h5");
  EXPECT_EQ(std::get<double>(a.at("time_bounds")), 0.25);
  EXPECT_EQ(std::get<double>(a.at("time_sort")), 2.0);
  EXPECT_EQ(std::get<double>(a.at("time_narrow")), 0.125);
}

TEST_F(Hdf5Io, ContactFilesAreByteIdentical) {
  for (const char* name : {"a.h5", "b.h5"})
    cg::write_contacts(path(name), sample_contacts<float>(1000, true), sample_info("fp32"));
  EXPECT_EQ(file_bytes(path("a.h5")), file_bytes(path("b.h5")));
  cg::RunInfo other = sample_info("fp32");
  other.times = {{"bounds", 9.0}};
  other.input = "elsewhere.h5";
  cg::write_contacts(path("c.h5"), sample_contacts<float>(1000, true), other);
  for (const char* name :
       {"id_a", "id_b", "position_on_a", "normal_on_b", "distance", "lateral_friction_dir2"}) {
    std::string dataset = std::string("/contacts/") + name;
    EXPECT_EQ(cg::read_dataset_bytes(path("a.h5"), dataset), cg::read_dataset_bytes(path("c.h5"), dataset))
        << name;
  }
  EXPECT_EQ(cg::read_dataset_bytes(path("a.h5"), "/contacts/distance").size(), 1000 * sizeof(float));
}

TEST_F(Hdf5Io, ContactsReplaceAnExistingFile) {
  { std::ofstream(path("c.h5")) << "old"; }
  cg::write_contacts(path("c.h5"), sample_contacts<double>(3, false), sample_info(""));
  EXPECT_EQ(cg::read_contacts(path("c.h5")).contacts.size(), 3u);
  EXPECT_EQ(entries(), std::vector<std::string>{"c.h5"});
}

TEST_F(Hdf5Io, WriteContactsIntoMissingDirectoryThrowsIoError) {
  std::string file = path("missing/c.h5");
  std::string msg = error_of<IoError>(
      [&] { cg::write_contacts(file, sample_contacts<double>(3, false), sample_info("fp64")); });
  EXPECT_CONTAINS(msg, file);
  EXPECT_FALSE(fs::exists(file));
  EXPECT_FALSE(fs::exists(path("missing")));
  EXPECT_TRUE(entries().empty());
}

TEST_F(Hdf5Io, FailedRenameRemovesTheTemporary) {
  fs::create_directories(path("c.h5/inside"));  // a non-empty directory: rename over it fails
  std::string msg = error_of<IoError>(
      [&] { cg::write_contacts(path("c.h5"), sample_contacts<float>(3, true), sample_info("fp32")); });
  EXPECT_CONTAINS(msg, path("c.h5"));
  EXPECT_EQ(entries(), std::vector<std::string>{"c.h5"});
  EXPECT_TRUE(fs::is_directory(path("c.h5")));
}

TEST_F(Hdf5Io, WriteSceneIntoMissingDirectoryThrowsIoError) {
  std::string file = path("missing/s.h5");
  std::string msg = error_of<IoError>([&] { cg::write_scene(file, sphere_scene(3)); });
  EXPECT_CONTAINS(msg, file);
  EXPECT_TRUE(entries().empty());
}

TEST_F(Hdf5Io, SceneWriterWithoutCommitLeavesNothing) {
  {
    cg::SceneFileHeader header;
    header.spheres = 2;
    cg::SceneFileWriter writer(path("s.h5"), header);
    std::vector<Vec3<double>> p{{0, 0, 0}};
    std::vector<double> r{1};
    writer.write_spheres(0, p, r);
  }
  EXPECT_TRUE(entries().empty());
}

TEST_F(Hdf5Io, ContactsPrecisionMismatchIsRejected) {
  EXPECT_THROW(cg::write_contacts(path("c.h5"), sample_contacts<float>(2, false), sample_info("fp64")),
               cg::Error);
  EXPECT_TRUE(entries().empty());
}

}  // namespace
