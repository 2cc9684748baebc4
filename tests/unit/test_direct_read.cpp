// Scene rows read straight from the file (pread on all threads, src/io/datasets.hpp read_rows_f64)
// against HDF5's own read (CONTACTGRID_IO_READ=hdf5): float64 and float32 storage (widened to double
// as HDF5 converts), spheres, ellipsoids and both, large enough for many blocks on several threads —
// the same doubles bit for bit; chunked storage falls back to HDF5 with the same result; a truncated
// file is an InputError either way; an unknown knob value is refused.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "io/datasets.hpp"
#include "io/inspect.hpp"
#include "io/scene_file.hpp"
#include "temp_dir.hpp"

namespace cg::test {
namespace {

// CONTACTGRID_IO_READ set for a scope (restored after).
class ReadKnob {
 public:
  explicit ReadKnob(const char* value) {
    if (const char* old = std::getenv("CONTACTGRID_IO_READ")) m_old = old;
    ::setenv("CONTACTGRID_IO_READ", value, 1);
  }
  ~ReadKnob() {
    if (m_old.empty())
      ::unsetenv("CONTACTGRID_IO_READ");
    else
      ::setenv("CONTACTGRID_IO_READ", m_old.c_str(), 1);
  }
  ReadKnob(const ReadKnob&) = delete;
  ReadKnob& operator=(const ReadKnob&) = delete;

 private:
  std::string m_old;
};

template <class V>
bool same_bits(const V& a, const V& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])) == 0);
}

// read_scene of `file` both ways: every array the same bits.
void expect_same_scene_either_way(const std::string& file, std::size_t spheres, std::size_t ellipsoids) {
  Scene direct, hdf5;
  {
    ReadKnob knob("direct");
    direct = read_scene(file);
  }
  {
    ReadKnob knob("hdf5");
    hdf5 = read_scene(file);
  }
  ASSERT_EQ(direct.sphere_count(), spheres);
  ASSERT_EQ(direct.ellipsoid_count(), ellipsoids);
  EXPECT_TRUE(same_bits(direct.sphere_position, hdf5.sphere_position));
  EXPECT_TRUE(same_bits(direct.sphere_radius, hdf5.sphere_radius));
  EXPECT_TRUE(same_bits(direct.ellipsoid_position, hdf5.ellipsoid_position));
  EXPECT_TRUE(same_bits(direct.ellipsoid_semi_axes, hdf5.ellipsoid_semi_axes));
  EXPECT_TRUE(same_bits(direct.ellipsoid_orientation, hdf5.ellipsoid_orientation));
}

// n spheres (positions not exact in float32) of `type` into `file`.
void write_spheres(const std::string& file, std::size_t n, RawType position_type, RawType radius_type) {
  std::vector<double> position(3 * n), radius(n);
  for (std::size_t i = 0; i < n; ++i) {
    position[3 * i] = 0.1 * double(i);
    position[3 * i + 1] = -1e5 + 0.37 * double(i % 1000);
    position[3 * i + 2] = 1.0 / double(i + 3);
    radius[i] = 0.01 + 1e-7 * double(i % 977);
  }
  write_raw_dataset(file, "/spheres/position", position_type, {n, 3}, position);
  write_raw_dataset(file, "/spheres/radius", radius_type, {n}, radius);
}

void write_ellipsoids(const std::string& file, std::size_t n, RawType type) {
  std::vector<double> position(3 * n), axes(3 * n), orientation(4 * n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) {
      position[3 * i + c] = 0.3 * double(i) + 0.1 * c;
      axes[3 * i + c] = 0.02 + 1e-3 * double((i + c) % 7);
    }
    orientation[4 * i + i % 4] = 1.0;  // unit quaternions, exact in float32
  }
  write_raw_dataset(file, "/ellipsoids/position", type, {n, 3}, position);
  write_raw_dataset(file, "/ellipsoids/semi_axes", type, {n, 3}, axes);
  write_raw_dataset(file, "/ellipsoids/orientation", type, {n, 4}, orientation);
}

class DirectRead : public TempDirTest {};

// 400 000 float32 spheres: 4.8 MB of positions, several 4 MiB blocks on several threads.
TEST_F(DirectRead, Float32SpheresAreTheSameEitherWay) {
  write_spheres(path("s.h5"), 400000, RawType::float32, RawType::float32);
  expect_same_scene_either_way(path("s.h5"), 400000, 0);
}

TEST_F(DirectRead, Float64SpheresAreTheSameEitherWay) {
  write_spheres(path("s.h5"), 300000, RawType::float64, RawType::float64);
  expect_same_scene_either_way(path("s.h5"), 300000, 0);
}

TEST_F(DirectRead, Float32EllipsoidsAreTheSameEitherWay) {
  write_ellipsoids(path("e.h5"), 200000, RawType::float32);
  expect_same_scene_either_way(path("e.h5"), 0, 200000);
}

// float64 positions with float32 radii, and float32 ellipsoids beside them; one row of each too.
TEST_F(DirectRead, MixedStorageTypesAreTheSameEitherWay) {
  write_spheres(path("m.h5"), 100001, RawType::float64, RawType::float32);
  write_ellipsoids(path("m.h5"), 70001, RawType::float32);
  expect_same_scene_either_way(path("m.h5"), 100001, 70001);
  write_spheres(path("one.h5"), 1, RawType::float32, RawType::float32);
  write_ellipsoids(path("one.h5"), 1, RawType::float32);
  expect_same_scene_either_way(path("one.h5"), 1, 1);
}

// Chunked float32 storage is read by HDF5 whatever the knob says (the same values).
TEST_F(DirectRead, ChunkedStorageFallsBackToHdf5) {
  const std::size_t n = 50000;
  write_spheres(path("c.h5"), n, RawType::float32, RawType::float32);
  // the positions again, chunked, in place of the contiguous ones
  std::vector<float> position(3 * n);
  for (std::size_t i = 0; i < 3 * n; ++i) position[i] = float(i % 4096) * 0.5f;
  const hid_t file = H5Fopen(path("c.h5").c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  ASSERT_GE(H5Ldelete(file, "/spheres/position", H5P_DEFAULT), 0);
  const hsize_t dims[2] = {n, 3}, chunk[2] = {4096, 3};
  const hid_t space = H5Screate_simple(2, dims, nullptr), dcpl = H5Pcreate(H5P_DATASET_CREATE);
  H5Pset_chunk(dcpl, 2, chunk);
  const hid_t d =
      H5Dcreate2(file, "/spheres/position", H5T_IEEE_F32LE, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
  ASSERT_GE(d, 0);
  ASSERT_GE(H5Dwrite(d, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, position.data()), 0);
  H5Dclose(d);
  H5Pclose(dcpl);
  H5Sclose(space);
  H5Fclose(file);
  expect_same_scene_either_way(path("c.h5"), n, 0);
  EXPECT_EQ(read_scene(path("c.h5")).sphere_position[n - 1].z, double(position[3 * n - 1]));
}

// A file cut short inside the float32 positions: InputError either way, nothing read past the end.
TEST_F(DirectRead, TruncatedFloat32FileIsAnInputErrorEitherWay) {
  write_spheres(path("t.h5"), 400000, RawType::float32, RawType::float32);
  std::filesystem::resize_file(path("t.h5"), std::filesystem::file_size(path("t.h5")) - 3000000);
  for (const char* mode : {"direct", "hdf5"}) {
    SCOPED_TRACE(mode);
    ReadKnob knob(mode);
    EXPECT_THROW(read_scene(path("t.h5")), InputError);
  }
}

TEST_F(DirectRead, KnobRefusesOtherValues) {
  {
    ReadKnob knob("");
    EXPECT_EQ(h5::read_mode(), h5::ReadMode::direct);
  }
  {
    ReadKnob knob("hdf5");
    EXPECT_EQ(h5::read_mode(), h5::ReadMode::hdf5);
  }
  ReadKnob knob("mmap");
  EXPECT_THROW(h5::read_mode(), UsageError);
}

}  // namespace
}  // namespace cg::test
