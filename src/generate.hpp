#pragma once
// Scene generators (course Project 1 scenes), seeded and reproducible. See generate.cpp.
#include <cstdint>
#include <string>

#include "scene.hpp"

namespace cg {

struct GenerateOptions {
  std::string kind = "uniform";      // uniform | polydisperse
  std::uint64_t count = 1024;        // N, 1 … 2^28
  std::uint64_t seed = 1;
  double radius_low = 0.5;           // Rlow
  double radius_high = 1.0;          // Rhigh (polydisperse: default Rlow·1000 … see --ratio)
  double contacts_per_body = 0.4;    // target density (course: 0.4)
  Vec3<double> offset{0, 0, 0};      // translation of the whole scene (far-from-origin tests)
};

// Edge L of the cube such that n(n-1)/2 · E[P((r1+r2)/L)] = contacts_per_body · n for radii
// uniform in [r_low, r_high] (P: probability that two uniform points of a unit cube lie within t).
double uniform_box_edge(std::uint64_t n, double r_low, double r_high, double contacts_per_body);

// In memory (tests, small N).
Scene generate_scene(const GenerateOptions& options);

// Streams the scene to an HDF5 file in chunks (any N up to 2^28 within bounded host memory),
// written to a temporary name and renamed. Root attributes record every option and the seed.
void generate_scene_file(const std::string& path, const GenerateOptions& options);

}  // namespace cg
