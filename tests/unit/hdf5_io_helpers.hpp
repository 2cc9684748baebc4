#pragma once
// The HDF5 layer tests' shared pieces (test_hdf5_io.cpp: round trips, test_hdf5_phased.cpp: the phased
// contact writer, test_hdf5_bad_input.cpp: bad and damaged input): the fixture (a temporary directory per
// test; in a named namespace, since its tests are in three files and GoogleTest wants one fixture class
// per suite), the exception check, and the scenes, contacts and raw datasets the tests write.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <exception>
#include <string>
#include <vector>

#include "io/contact_file.hpp"
#include "io/inspect.hpp"
#include "io/scene_file.hpp"
#include "temp_dir.hpp"

#define EXPECT_CONTAINS(text, part)                          \
  EXPECT_NE(std::string(text).find(part), std::string::npos) \
      << "message \"" << (text) << "\" does not contain \"" << (part) << "\""

namespace cg::test {

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

class Hdf5Io : public TempDirTest {};

inline Scene sphere_scene(std::size_t n) {
  Scene s;
  for (std::size_t i = 0; i < n; ++i) {
    s.sphere_position.push_back({1.5 * i, -0.25 * i, 1e6 + 0.1 * i});
    s.sphere_radius.push_back(0.5 + 0.001 * i);
  }
  return s;
}

inline Scene mixed_scene() {
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

inline cg::RunInfo sample_info(const char* precision) {
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

// Writes /spheres with n rows through the raw helper (float64 unless told).
inline void write_raw_spheres(const std::string& file, const std::vector<double>& position,
                              const std::vector<double>& radius, RawType type = RawType::float64) {
  cg::write_raw_dataset(file, "/spheres/position", type, {position.size() / 3, 3}, position);
  cg::write_raw_dataset(file, "/spheres/radius", type, {radius.size()}, radius);
}

}  // namespace cg::test
