#pragma once
// HDF5 I/O of CONTRACT §1 and §2, behind thin RAII wrappers of the HDF5 C API (hdf5_io.cpp).
//
// Reading validates everything it reads and throws InputError with one message naming the file, the
// dataset and the first bad row ("scene.h5: /spheres/radius row 17: radius -1 is not > 0"); a file
// that cannot be opened or is truncated is an InputError naming the file.
// Writing goes to "<path>.tmp.<pid>" and is renamed over <path> only after the file is closed, so an
// output file exists only for a successful run (IoError otherwise, temporary removed).
#include <cstdint>
#include <string>

#include "engine.hpp"
#include "scene.hpp"

namespace cg {

// Whole scene into memory (double), validated. Rows [first, first+count) of each group can be read
// with read_scene_rows for parallel readers.
Scene read_scene(const std::string& path);

// Counts of bodies in a scene file without reading the data.
struct SceneShape {
  std::size_t spheres = 0, ellipsoids = 0;
};
SceneShape read_scene_shape(const std::string& path);

// Rows [first, first + count) of /spheres (positions, radii) — validated like read_scene, with the
// row numbers of the file in messages. Root attributes are read too.
Scene read_scene_rows(const std::string& path, std::size_t first, std::size_t count);

void write_scene(const std::string& path, const Scene& scene);

// Everything recorded about a run in the contact file's root attributes (CONTRACT §2).
struct RunInfo {
  std::uint64_t bodies = 0;
  std::string precision;  // "fp32" | "fp64"
  std::string backend;    // "cpu" | "cuda"
  int ranks = 1;
  double cell_size = 0;
  std::string input;      // input file name
  StageTimes times;
};

template <class Real>
void write_contacts(const std::string& path, const Contacts<Real>& contacts, const RunInfo& info);

// Reads a contact file back in double (whatever precision it was written in).
struct ContactFile {
  Contacts<double> contacts;
  std::string precision;
  Attributes attributes;
};
ContactFile read_contacts(const std::string& path);

}  // namespace cg
