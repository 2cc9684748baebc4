// Unit tests of the HDF5 layer (src/io/): scene and contact round trips, and one test per
// kind of bad input, each checking the exception type and that the message names the file, the
// dataset and the row. Every test works in its own temporary directory, removed afterwards.
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

#include "io/contact_file.hpp"
#include "io/inspect.hpp"
#include "io/scene_file.hpp"
#include "support/contacts_equal.hpp"
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

#define EXPECT_CONTAINS(text, part)                          \
  EXPECT_NE(std::string(text).find(part), std::string::npos) \
      << "message \"" << (text) << "\" does not contain \"" << (part) << "\""

// Runs f, expects exactly an exception of type E, returns its message ("" otherwise).
template <class E, class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const E& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type: " << e.what();
    return "";
  }
  ADD_FAILURE() << "no exception thrown";
  return "";
}

std::vector<unsigned char> file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

class Hdf5Io : public cg::test::TempDirTest {};

Scene sphere_scene(std::size_t n) {
  Scene s;
  for (std::size_t i = 0; i < n; ++i) {
    s.sphere_position.push_back({1.5 * i, -0.25 * i, 1e6 + 0.1 * i});
    s.sphere_radius.push_back(0.5 + 0.001 * i);
  }
  return s;
}

Scene mixed_scene() {
  Scene s = sphere_scene(6);
  for (int i = 0; i < 4; ++i) {
    s.ellipsoid_position.push_back({10.0 + i, 20.0, -3.0 * i});
    s.ellipsoid_semi_axes.push_back({0.5, 0.75, 1.0 - 0.1 * i});
    double a = 0.3 * i;
    s.ellipsoid_orientation.push_back({std::cos(a), 0.0, std::sin(a), 0.0});
  }
  s.radius_low = 0.25;
  s.radius_high = 2.0;
  s.attributes["generator"] = std::string("test");
  s.attributes["count"] = std::int64_t{10};
  s.attributes["seed"] = std::int64_t{-5};
  s.attributes["box_edge"] = 12.5;
  return s;
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
Contacts<Real> sample_contacts(std::size_t k, bool full) {
  Contacts<Real> c;
  c.full = full;
  for (std::size_t i = 0; i < k; ++i) {
    Real f = static_cast<Real>(i);
    c.id_a.push_back(static_cast<std::int64_t>(i));
    c.id_b.push_back(static_cast<std::int64_t>(i + 1 + (std::int64_t(1) << 33)));
    c.position_on_a.push_back({f, f + Real(0.1), -f});
    c.position_on_b.push_back({f + Real(0.2), f, Real(1) / (f + 1)});
    c.normal_on_b.push_back({Real(1), Real(0), Real(0)});
    c.distance.push_back(-Real(0.01) * f);
    if (full) {
      c.local_point_a.push_back({Real(0.5), f, Real(0)});
      c.local_point_b.push_back({-Real(0.5), Real(0), f});
      c.lateral_friction_dir1.push_back({Real(0), Real(1), Real(0)});
      c.lateral_friction_dir2.push_back({Real(0), Real(0), Real(1)});
    }
  }
  return c;
}

cg::RunInfo sample_info(const char* precision) {
  cg::RunInfo info;
  info.bodies = 1234;
  info.precision = precision;
  info.backend = "cpu";
  info.ranks = 3;
  info.cell_size = 2.5;
  info.input = "scene.h5";
  info.times = {{"bounds", 0.25}, {"sort", 1.5}, {"narrow", 0.125}};
  return info;
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

// Writes /spheres with n rows through the raw helper (float64 unless told).
void write_raw_spheres(const std::string& file, const std::vector<double>& position,
                       const std::vector<double>& radius, RawType type = RawType::float64) {
  cg::write_raw_dataset(file, "/spheres/position", type, {position.size() / 3, 3}, position);
  cg::write_raw_dataset(file, "/spheres/radius", type, {radius.size()}, radius);
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

// ---- the phased contact writer (create, rows by pwrite from anywhere, commit) --------------------------

// Rows [from, from + n) of c.
template <class Real>
Contacts<Real> slice_of(const Contacts<Real>& c, std::size_t from, std::size_t n) {
  Contacts<Real> s;
  s.full = c.full;
  cg::zip_contact_fields(s, c, true, [&](auto, auto& dst, const auto& src) {
    if (!src.empty()) dst.assign(src.begin() + from, src.begin() + from + n);
  });
  return s;
}

// Uneven slices (one row, empty, large, ...) written in a scrambled order with varying thread counts,
// through the layout's text form (as another process receives it): the file reads back as the
// contacts, and its datasets are byte for byte those of the one-call writer.
template <class Real>
void phased_round_trip(const std::string& dir, std::size_t k, bool full) {
  const bool fp32 = std::is_same_v<Real, float>;
  const Contacts<Real> c = sample_contacts<Real>(k, full);
  const std::string file = dir + "/phased.h5", whole = dir + "/whole.h5";
  cg::write_contacts(whole, c, sample_info(fp32 ? "fp32" : "fp64"), 1);
  const cg::ContactFileLayout layout =
      cg::create_contact_file(file, k, fp32 ? cg::Precision::fp32 : cg::Precision::fp64, full);
  const cg::ContactFileLayout remote = cg::ContactFileLayout::from_text(layout.to_text());
  std::vector<std::size_t> cuts{0,
                                std::min<std::size_t>(1, k),
                                std::min<std::size_t>(1, k),
                                k / 3,
                                k / 3 + std::min<std::size_t>(7, k - k / 3),
                                k};
  std::sort(cuts.begin(), cuts.end());
  const std::size_t order[] = {3, 0, 4, 2, 1};
  int threads = 1;
  for (std::size_t j : order) {
    cg::write_contact_rows(remote, cuts[j], slice_of(c, cuts[j], cuts[j + 1] - cuts[j]), threads);
    threads = threads % 3 + 1;
  }
  cg::commit_contact_file(layout, sample_info(fp32 ? "fp32" : "fp64"));
  cg::ContactFile back = cg::read_contacts(file);
  EXPECT_EQ(back.precision, fp32 ? "fp32" : "fp64");
  EXPECT_EQ(back.contacts.full, full);
  ASSERT_EQ(back.contacts.size(), k);
  EXPECT_EQ(cg::test::compare_contacts(c, back.contacts), "identical");
  EXPECT_EQ(std::get<std::int64_t>(back.attributes.at("contacts")), static_cast<std::int64_t>(k));
  for (std::size_t d = 0; d < (full ? 10u : 6u); ++d) {
    EXPECT_EQ(cg::inspect_dataset(file, cg::kContactFields[d].path)->dims,
              cg::inspect_dataset(whole, cg::kContactFields[d].path)->dims);
    EXPECT_EQ(cg::read_dataset_bytes(file, cg::kContactFields[d].path),
              cg::read_dataset_bytes(whole, cg::kContactFields[d].path))
        << cg::kContactFields[d].path;
  }
  if (!full) {
    EXPECT_FALSE(cg::inspect_dataset(file, "/contacts/local_point_a").has_value());
  }
}

TEST_F(Hdf5Io, PhasedContactsFp64Basic) { phased_round_trip<double>(m_dir.string(), 1000, false); }
TEST_F(Hdf5Io, PhasedContactsFp32Basic) { phased_round_trip<float>(m_dir.string(), 1000, false); }
TEST_F(Hdf5Io, PhasedContactsFp64Full) { phased_round_trip<double>(m_dir.string(), 1000, true); }
TEST_F(Hdf5Io, PhasedContactsFp32Full) { phased_round_trip<float>(m_dir.string(), 1000, true); }
TEST_F(Hdf5Io, PhasedContactsOneRow) { phased_round_trip<double>(m_dir.string(), 1, true); }
TEST_F(Hdf5Io, PhasedContactsEmptyFp64) { phased_round_trip<double>(m_dir.string(), 0, false); }
TEST_F(Hdf5Io, PhasedContactsEmptyFp32Full) { phased_round_trip<float>(m_dir.string(), 0, true); }

// Blocks of the writer are 4 MiB: 300 000 fp64 rows make several per vector dataset, written by
// several threads at once.
TEST_F(Hdf5Io, PhasedContactsManyBlocksManyThreads) {
  phased_round_trip<double>(m_dir.string(), 300000, true);
}

TEST_F(Hdf5Io, ContactFileLayoutTextRoundTrip) {
  cg::ContactFileLayout l;
  l.path = "dir with space/out\nnewline.h5";
  l.temp = l.path + ".tmp.17";
  l.rows = (std::uint64_t(1) << 40) + 3;
  l.precision = cg::Precision::fp32;
  l.fields = {true, true};
  l.datasets = {{"/contacts/id_a", 4096, 8}, {"/contacts/normal_on_b", (std::uint64_t(1) << 50), 12}};
  const cg::ContactFileLayout b = cg::ContactFileLayout::from_text(l.to_text());
  EXPECT_EQ(b.path, l.path);
  EXPECT_EQ(b.temp, l.temp);
  EXPECT_EQ(b.rows, l.rows);
  EXPECT_EQ(b.precision, l.precision);
  EXPECT_EQ(b.fields, l.fields);
  ASSERT_EQ(b.datasets.size(), 2u);
  EXPECT_EQ(b.datasets[1].name, "/contacts/normal_on_b");
  EXPECT_EQ(b.datasets[1].offset, std::uint64_t(1) << 50);
  EXPECT_EQ(b.datasets[1].row_bytes, 12u);
  EXPECT_THROW(cg::ContactFileLayout::from_text("garbage"), cg::Error);
}

TEST_F(Hdf5Io, PhasedRowsOutsideTheFileAreRejectedAndDiscardLeavesNothing) {
  const Contacts<double> c = sample_contacts<double>(10, false);
  const cg::ContactFileLayout layout = cg::create_contact_file(path("c.h5"), 10, cg::Precision::fp64, false);
  EXPECT_THROW(cg::write_contact_rows(layout, 5, slice_of(c, 0, 6)), cg::Error);
  EXPECT_THROW(cg::write_contact_rows(layout, 11, slice_of(c, 0, 0)), cg::Error);
  // precision and fields must match the file
  EXPECT_THROW(cg::write_contact_rows(layout, 0, sample_contacts<float>(2, false)), cg::Error);
  EXPECT_THROW(cg::write_contact_rows(layout, 0, sample_contacts<double>(2, true)), cg::Error);
  cg::discard_contact_file(layout);
  cg::discard_contact_file(layout);  // twice: no error
  EXPECT_TRUE(entries().empty());
}

// A write that fails in the row phase (the temporary is a link to /dev/full: every pwrite ENOSPC) is
// an IoError naming the file and the dataset; discarding leaves neither output nor temporary.
TEST_F(Hdf5Io, PhasedWriteFailureNamesTheDatasetAndLeavesNothing) {
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  const cg::ContactFileLayout layout = cg::create_contact_file(path("c.h5"), 10, cg::Precision::fp64, true);
  fs::remove(layout.temp);
  fs::create_symlink("/dev/full", layout.temp);
  std::string msg =
      error_of<IoError>([&] { cg::write_contact_rows(layout, 2, sample_contacts<double>(3, true), 2); });
  EXPECT_CONTAINS(msg, path("c.h5"));
  EXPECT_CONTAINS(msg, "/contacts/id_a");
  EXPECT_CONTAINS(msg, "rows 2 to 4");
  cg::discard_contact_file(layout);
  EXPECT_TRUE(entries().empty());
  EXPECT_TRUE(fs::exists("/dev/full"));
}

TEST_F(Hdf5Io, PhasedCommitFailureRemovesTheTemporary) {
  fs::create_directories(path("c.h5/inside"));  // rename over a non-empty directory fails
  const cg::ContactFileLayout layout = cg::create_contact_file(path("c.h5"), 3, cg::Precision::fp32, false);
  cg::write_contact_rows(layout, 0, sample_contacts<float>(3, false));
  std::string msg = error_of<IoError>([&] { cg::commit_contact_file(layout, sample_info("fp32")); });
  EXPECT_CONTAINS(msg, path("c.h5"));
  EXPECT_EQ(entries(), std::vector<std::string>{"c.h5"});
}

TEST_F(Hdf5Io, PhasedCreateIntoMissingDirectoryLeavesNothing) {
  std::string msg = error_of<IoError>(
      [&] { cg::create_contact_file(path("missing/c.h5"), 3, cg::Precision::fp64, false); });
  EXPECT_CONTAINS(msg, path("missing/c.h5"));
  EXPECT_TRUE(entries().empty());
}

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
  const fs::path dir = fs::path(CG_SOURCE_DIR) / "tests/data/damaged";
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
  const fs::path dir = fs::path(CG_SOURCE_DIR) / "tests/data/damaged";
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
