#pragma once
// Scene generators (course Project 1 scenes), seeded and reproducible. See generate.cpp.
//
// Every random value is a pure function of (seed, body index, stream), so body i is the same whatever
// the chunking, the thread count or the entry point (generate_scene == read_scene(generate_scene_file)).
#include <cstdint>
#include <string>

#include "scene/scene.hpp"

namespace cg {

struct GenerateOptions {
  std::string kind = "uniform";  // uniform | polydisperse | ellipsoids | mixed | bimodal | intruders
  std::uint64_t count = 1024;    // N, 1 … 2^28
  std::uint64_t seed = 1;
  double radius_low = 0.5;          // Rlow
  double radius_high = 1.0;         // Rhigh (polydisperse: default Rlow·1000 … see --ratio)
  double contacts_per_body = 0.4;   // target density (course: 0.4)
  Vec3<double> offset{0, 0, 0};     // translation of the whole scene (far-from-origin tests)
  double ellipsoid_fraction = 0.5;  // mixed: share of ellipsoids, in [0, 1]
  double large_fraction = 0.1;      // bimodal: share of the bodies' volume in the large ones, in [0, 1]
  std::uint64_t intruders = 64;     // intruders: how many large bodies, 1 … count
};

// How many of options.count bodies are ellipsoids: ellipsoids: all; mixed: round(F·count); else 0.
std::uint64_t generated_ellipsoids(const GenerateOptions& options);

// Two-size scenes (bimodal, intruders): how many of options.count bodies have radius_high, the rest
// radius_low. bimodal: the count whose volume share is large_fraction, round(count·q) with
// q = x / (1 + x), x = F / (1 − F) · (r_low / r_high)³ (F = 1: all); intruders: min(intruders, count);
// else 0. The large ones are spread evenly over the ids: body i is large iff
// floor((i + 1)·k / count) > floor(i·k / count).
std::uint64_t generated_large(const GenerateOptions& options);
bool generated_is_large(std::uint64_t i, std::uint64_t large, std::uint64_t count);

inline constexpr std::uint64_t kMaxGenerateCount = std::uint64_t(1) << 28;
inline constexpr double kMaxPolydisperseRatio = 1000;  // radius_high / radius_low (also bimodal, intruders)

// Edge L of the cube such that n(n-1)/2 · E[P((r1+r2)/L)] = contacts_per_body · n for radii
// uniform in [r_low, r_high] (P: probability that two uniform points of a unit cube lie within t).
double uniform_box_edge(std::uint64_t n, double r_low, double r_high, double contacts_per_body);

// ---- the density model behind the box edges (generate.cpp documents the numerics) ----------------

// P(t): probability that two independent uniform points of the unit cube are within distance t.
// Exact polynomial for t <= 1, exact integral (tabulated) for 1 < t < √3, 1 beyond; continuous and
// non-decreasing.
double cube_distance_cdf(double t);

// Law of the radii of a generated scene on [r_low, r_high]. max_of_three_uniform: the bounding radius
// of an ellipsoid whose three semi-axes are uniform on [r_low, r_high].
enum class RadiusLaw { uniform, log_uniform, max_of_three_uniform };

// E[P((r1 + r2) / edge)] for independent r1, r2 with the law (Gauss–Legendre quadrature).
double expected_pair_contact(double edge, RadiusLaw law, double r_low, double r_high);

// The edge L solving n(n-1)/2 · E[P((r1+r2)/L)] = c·n (bisection). When even "every pair in
// contact" is not dense enough (n - 1 < 2c, e.g. n = 1) it returns the largest edge at which every
// pair is in contact, 2·r_low/√3. Throws UsageError for n = 0, radii not 0 < r_low <= r_high, c <= 0.
double box_edge(std::uint64_t n, RadiusLaw law, double r_low, double r_high, double contacts_per_body);
double polydisperse_box_edge(std::uint64_t n, double r_low, double r_high, double contacts_per_body);

// Throws UsageError unless: kind is uniform|polydisperse|ellipsoids|mixed|bimodal|intruders (mixed:
// ellipsoid_fraction in [0, 1]; bimodal: large_fraction in [0, 1]; intruders: intruders in [1, count]),
// count in [1, 2^28], finite radii with 0 < radius_low <= radius_high (polydisperse, bimodal,
// intruders: ratio <= 1000), finite contacts_per_body > 0, finite offset.
void validate_generate_options(const GenerateOptions& options);

// The box edge the options' scene uses (validates the options).
double scene_box_edge(const GenerateOptions& options);

// ---- generators ---------------------------------------------------------------------------------

// In memory (tests, small N). uniform: radii uniform in [Rlow, Rhigh]; polydisperse: log-uniform;
// bimodal and intruders: two radii, Rhigh for generated_large() bodies and Rlow for the rest —
// bimodal's box edge from the mixture of the two (contacts_per_body over all bodies), intruders' from
// the small bodies alone (the grains keep the uniform scene's density; the intruders add theirs).
// ellipsoids: every body an ellipsoid, semi-axes each uniform in [Rlow, Rhigh], orientation uniform
// on SO(3); mixed: spheres (uniform radii) then ellipsoids (generated_ellipsoids of them); the box
// edge from the bounding radii's law. Body id i draws from index i whatever its kind.
// Centres uniform in [0, L)^3 + offset. radius_low/radius_high are set; attributes hold the rest
// (generator, count, seed, contacts_per_body, box_edge, offset_x/y/z, software_version; with
// ellipsoids also spheres, ellipsoids, and for mixed ellipsoid_fraction; bimodal and intruders: large,
// and large_fraction or intruders).
Scene generate_scene(const GenerateOptions& options);

// Streams the scene to an HDF5 file in chunks (any N up to 2^28 within bounded host memory),
// written to a temporary name and renamed. Root attributes record every option and the seed.
// `progress`: a progress line of the bodies written (run/progress.hpp: on a terminal only).
void generate_scene_file(const std::string& path, const GenerateOptions& options, bool progress = false);

// ---- small deterministic builders for tests -------------------------------------------------------

// `clusters` dense Gaussian clusters (bodies assigned round-robin), radii uniform in [0.5, 1];
// sigma = max(1, cbrt(m / 12)) for m bodies per cluster, about 4 contacts per body near a cluster's
// centre; cluster centres uniform in a cube of edge 8·sigma·cbrt(clusters). n may be 0 (empty).
Scene make_clustered_scene(std::uint64_t n, std::uint64_t seed, int clusters = 4);

// A nx × ny × nz cubic lattice of equal spheres (x fastest): centre (i, j, k)·spacing + origin.
// spacing == 2·radius makes every axis neighbour touch exactly (distance 0).
Scene make_lattice_scene(std::uint32_t nx, std::uint32_t ny, std::uint32_t nz, double spacing, double radius,
                         Vec3<double> origin = {0, 0, 0});

// Spheres (radii uniform in [0.5, 1]) then ellipsoids (semi-axes uniform in [0.25, 1], uniformly
// random unit quaternions) at the 0.4-contacts-per-body density of their bounding spheres.
// radius_low = 0.25, radius_high = 1.
Scene make_ellipsoid_scene(std::uint64_t spheres, std::uint64_t ellipsoids, std::uint64_t seed);

namespace detail {
// P(t) for any t >= 0 straight from the integral (slow; the table behind cube_distance_cdf and a
// check of the polynomial in tests).
double cube_distance_cdf_integral(double t);
}  // namespace detail

}  // namespace cg
