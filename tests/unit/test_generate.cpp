// Unit tests of the scene generators (src/scene/generate.cpp): the density model (P(t), box edges against
// independent closed forms and Monte Carlo), determinism and chunk independence, the achieved
// density, the polydisperse radius law, option validation and the test-scene builders.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "io/contact_file.hpp"
#include "io/inspect.hpp"
#include "io/scene_file.hpp"
#include "scene/generate.hpp"
#include "temp_dir.hpp"

namespace {

namespace fs = std::filesystem;
using cg::GenerateOptions;
using cg::Scene;

class Generate : public cg::test::TempDirTest {
 protected:
  bool empty_dir() const { return entries().empty(); }
};

std::vector<unsigned char> file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Pairs of spheres with |a − b| <= ra + rb (O(n²): small scenes only).
std::uint64_t count_pairs(const Scene& s) {
  std::uint64_t pairs = 0;
  const std::size_t n = s.sphere_count();
  for (std::size_t i = 0; i < n; ++i) {
    const auto a = s.sphere_position[i];
    for (std::size_t j = i + 1; j < n; ++j) {
      const auto b = s.sphere_position[j];
      double dx = a.x - b.x, dy = a.y - b.y, dz = a.z - b.z, r = s.sphere_radius[i] + s.sphere_radius[j];
      pairs += dx * dx + dy * dy + dz * dz <= r * r ? 1 : 0;
    }
  }
  return pairs;
}

void expect_same_bodies(const Scene& a, const Scene& b) {
  ASSERT_EQ(a.sphere_count(), b.sphere_count());
  for (std::size_t i = 0; i < a.sphere_count(); ++i) {
    ASSERT_TRUE(a.sphere_position[i] == b.sphere_position[i]) << "body " << i;
    ASSERT_EQ(a.sphere_radius[i], b.sphere_radius[i]) << "body " << i;
  }
}

// The box edge from the closed form valid when every t = (r1 + r2)/L <= 1: E[P] = Σ c_k E[s^k]/L^k
// with s = r1 + r2 and E[r^j] the law's moments; solved by plain bisection.
double edge_from_moments(std::uint64_t n, const std::vector<double>& radius_moment, double c) {
  auto binomial = [](int k, int j) {
    double b = 1;
    for (int i = 1; i <= j; ++i) b = b * (k - j + i) / i;
    return b;
  };
  std::vector<double> s_moment(7, 0.0);
  for (int k = 0; k <= 6; ++k)
    for (int j = 0; j <= k; ++j) s_moment[k] += binomial(k, j) * radius_moment[j] * radius_moment[k - j];
  const double pi = std::numbers::pi;
  const double coefficient[7] = {0, 0, 0, 4 * pi / 3, -1.5 * pi, 8.0 / 5, -1.0 / 6};
  auto excess = [&](double edge) {
    double e = 0;
    for (int k = 3; k <= 6; ++k) e += coefficient[k] * s_moment[k] / std::pow(edge, k);
    return 0.5 * double(n - 1) * e - c;
  };
  double lo = 1e-3, hi = 1e9;
  while (excess(lo) < 0) lo /= 2;
  for (int i = 0; i < 400; ++i) {
    double mid = 0.5 * (lo + hi);
    (excess(mid) > 0 ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

// ---- density model ---------------------------------------------------------------------------

TEST_F(Generate, CubeDistanceCdfPolynomialMatchesTheIntegral) {
  for (double t : {0.05, 0.3, 0.5, 0.77, 0.99, 1.0}) {
    double poly = cg::cube_distance_cdf(t);
    EXPECT_NEAR(poly, cg::detail::cube_distance_cdf_integral(t), 1e-9) << "t = " << t;
  }
  EXPECT_NEAR(cg::cube_distance_cdf(1.0), 4 * std::numbers::pi / 3 - 1.5 * std::numbers::pi + 1.6 - 1.0 / 6,
              1e-15);
}

TEST_F(Generate, CubeDistanceCdfIsContinuousAndMonotone) {
  EXPECT_EQ(cg::cube_distance_cdf(0), 0);
  EXPECT_EQ(cg::cube_distance_cdf(-1), 0);
  EXPECT_EQ(cg::cube_distance_cdf(std::sqrt(3.0)), 1);
  EXPECT_EQ(cg::cube_distance_cdf(5), 1);
  EXPECT_NEAR(cg::cube_distance_cdf(1 - 1e-9), cg::cube_distance_cdf(1 + 1e-9), 1e-7);
  EXPECT_NEAR(cg::cube_distance_cdf(std::sqrt(3.0) - 1e-9), 1.0, 1e-7);
  double previous = 0;
  for (int i = 1; i <= 4000; ++i) {
    double value = cg::cube_distance_cdf(i * 0.0005);
    ASSERT_GE(value, previous) << "t = " << i * 0.0005;
    previous = value;
  }
  for (double t : {1.1, 1.3, 1.5, 1.7})  // the table against the integral
    EXPECT_NEAR(cg::cube_distance_cdf(t), cg::detail::cube_distance_cdf_integral(t), 1e-7) << "t = " << t;
}

TEST_F(Generate, CubeDistanceCdfMatchesMonteCarlo) {
  std::mt19937_64 rng(12345);
  std::uniform_real_distribution<double> u(0, 1);
  const int samples = 1'000'000;
  const std::vector<double> ts{0.5, 1.2, 1.5};
  std::vector<int> hits(ts.size(), 0);
  for (int s = 0; s < samples; ++s) {
    double dx = u(rng) - u(rng), dy = u(rng) - u(rng), dz = u(rng) - u(rng);
    double d = std::sqrt(dx * dx + dy * dy + dz * dz);
    for (std::size_t k = 0; k < ts.size(); ++k) hits[k] += d <= ts[k] ? 1 : 0;
  }
  for (std::size_t k = 0; k < ts.size(); ++k) {
    double p = cg::cube_distance_cdf(ts[k]);
    double sigma = std::sqrt(p * (1 - p) / samples);
    EXPECT_NEAR(double(hits[k]) / samples, p, 5 * sigma) << "t = " << ts[k];
  }
}

TEST_F(Generate, UniformBoxEdgeForLargeN) {
  for (std::uint64_t n : {std::uint64_t(1) << 20, std::uint64_t(1) << 24, std::uint64_t(1) << 28}) {
    double edge = cg::uniform_box_edge(n, 0.5, 1.0, 0.4);
    EXPECT_NEAR(edge / (2.65 * std::cbrt(double(n))), 1.0, 0.01) << "n = " << n;
  }
}

TEST_F(Generate, UniformBoxEdgeMatchesTheClosedForm) {
  const double a = 0.5, b = 1.0;
  std::vector<double> moment(7);
  for (int j = 0; j <= 6; ++j) moment[j] = (std::pow(b, j + 1) - std::pow(a, j + 1)) / ((j + 1) * (b - a));
  for (std::uint64_t n : {std::uint64_t(100), std::uint64_t(1000), std::uint64_t(1) << 20}) {
    double expected = edge_from_moments(n, moment, 0.4);
    ASSERT_GT(expected, 2 * b);  // the closed form is valid
    EXPECT_NEAR(cg::uniform_box_edge(n, a, b, 0.4) / expected, 1.0, 1e-9) << "n = " << n;
  }
}

TEST_F(Generate, PolydisperseBoxEdgeMatchesTheClosedForm) {
  const double a = 0.01, b = 10.0;  // ratio 1000
  std::vector<double> moment(7);
  moment[0] = 1;
  for (int j = 1; j <= 6; ++j) moment[j] = (std::pow(b, j) - std::pow(a, j)) / (j * std::log(b / a));
  for (std::uint64_t n : {std::uint64_t(1000), std::uint64_t(1) << 20}) {
    double expected = edge_from_moments(n, moment, 0.4);
    ASSERT_GT(expected, 2 * b);
    EXPECT_NEAR(cg::polydisperse_box_edge(n, a, b, 0.4) / expected, 1.0, 1e-9) << "n = " << n;
  }
}

TEST_F(Generate, SmallCountsHaveSensibleEdges) {
  EXPECT_DOUBLE_EQ(cg::uniform_box_edge(1, 0.5, 1.0, 0.4),
                   1.0 / std::sqrt(3.0));  // every pair (none) touches
  for (std::uint64_t n : {2, 3, 5}) {
    double edge = cg::uniform_box_edge(n, 0.5, 1.0, 0.4);
    EXPECT_GT(edge, 0);
    double pairs =
        0.5 * double(n) * double(n - 1) * cg::expected_pair_contact(edge, cg::RadiusLaw::uniform, 0.5, 1.0);
    EXPECT_NEAR(pairs / double(n), 0.4, 1e-9) << "n = " << n;
  }
}

TEST_F(Generate, BoxEdgeRejectsBadArguments) {
  EXPECT_THROW(cg::uniform_box_edge(0, 0.5, 1.0, 0.4), cg::UsageError);
  EXPECT_THROW(cg::uniform_box_edge(10, 0.0, 1.0, 0.4), cg::UsageError);
  EXPECT_THROW(cg::uniform_box_edge(10, 2.0, 1.0, 0.4), cg::UsageError);
  EXPECT_THROW(cg::uniform_box_edge(10, 0.5, 1.0, 0.0), cg::UsageError);
  EXPECT_THROW(cg::uniform_box_edge(10, 0.5, NAN, 0.4), cg::UsageError);
}

// ---- generated scenes --------------------------------------------------------------------------

TEST_F(Generate, SameSeedSameBytesDifferentSeedDifferentBodies) {
  GenerateOptions o;
  o.count = 5000;
  o.seed = 42;
  cg::generate_scene_file(path("a.h5"), o);
  cg::generate_scene_file(path("b.h5"), o);
  EXPECT_EQ(file_bytes(path("a.h5")), file_bytes(path("b.h5")));
  o.seed = 43;
  cg::generate_scene_file(path("c.h5"), o);
  EXPECT_NE(cg::read_dataset_bytes(path("a.h5"), "/spheres/position"),
            cg::read_dataset_bytes(path("c.h5"), "/spheres/position"));
  EXPECT_NE(cg::read_dataset_bytes(path("a.h5"), "/spheres/radius"),
            cg::read_dataset_bytes(path("c.h5"), "/spheres/radius"));
}

TEST_F(Generate, InMemoryIsDeterministic) {
  GenerateOptions o;
  o.count = 3000;
  o.seed = 7;
  expect_same_bodies(cg::generate_scene(o), cg::generate_scene(o));
  Scene a = cg::generate_scene(o);
  o.seed = 8;
  Scene b = cg::generate_scene(o);
  std::size_t same = 0;
  for (std::size_t i = 0; i < a.sphere_count(); ++i)
    same += a.sphere_position[i] == b.sphere_position[i] ? 1 : 0;
  EXPECT_EQ(same, 0u);
}

TEST_F(Generate, FileMatchesMemoryAcrossChunks) {
  GenerateOptions o;
  o.count = (std::uint64_t(1) << 20) + 4321;  // two streamed blocks
  o.seed = 99;
  o.offset = {1e6, -2e6, 3.5};
  cg::generate_scene_file(path("g.h5"), o);
  Scene from_file = cg::read_scene(path("g.h5"));
  Scene in_memory = cg::generate_scene(o);
  expect_same_bodies(in_memory, from_file);
  EXPECT_EQ(from_file.radius_low, in_memory.radius_low);
  EXPECT_EQ(from_file.radius_high, in_memory.radius_high);
  EXPECT_EQ(from_file.attributes, in_memory.attributes);
}

TEST_F(Generate, PolydisperseFileMatchesMemory) {
  GenerateOptions o;
  o.kind = "polydisperse";
  o.count = 20000;
  o.radius_low = 0.01;
  o.radius_high = 10;
  cg::generate_scene_file(path("p.h5"), o);
  expect_same_bodies(cg::generate_scene(o), cg::read_scene(path("p.h5")));
}

TEST_F(Generate, RecordsOptionsAsAttributes) {
  GenerateOptions o;
  o.count = 100;
  o.seed = ~std::uint64_t(0);  // above int64: stored bit-cast
  o.contacts_per_body = 0.7;
  o.offset = {1, 2, 3};
  cg::generate_scene_file(path("g.h5"), o);
  Scene s = cg::read_scene(path("g.h5"));
  const cg::Attributes& a = s.attributes;
  EXPECT_EQ(std::get<std::string>(a.at("generator")), "uniform");
  EXPECT_EQ(std::get<std::int64_t>(a.at("count")), 100);
  EXPECT_EQ(std::get<std::int64_t>(a.at("seed")), -1);
  EXPECT_EQ(std::get<double>(a.at("contacts_per_body")), 0.7);
  EXPECT_EQ(std::get<double>(a.at("box_edge")), cg::uniform_box_edge(100, 0.5, 1.0, 0.7));
  EXPECT_EQ(std::get<double>(a.at("offset_x")), 1);
  EXPECT_EQ(std::get<double>(a.at("offset_y")), 2);
  EXPECT_EQ(std::get<double>(a.at("offset_z")), 3);
  EXPECT_EQ(std::get<std::string>(a.at("software_version")), CONTACTGRID_VERSION);
  EXPECT_EQ(s.radius_low, 0.5);
  EXPECT_EQ(s.radius_high, 1.0);
}

TEST_F(Generate, BodiesLieInTheOffsetBox) {
  GenerateOptions o;
  o.count = 10000;
  o.offset = {-1e5, 0, 1e3};
  Scene s = cg::generate_scene(o);
  double edge = std::get<double>(s.attributes.at("box_edge"));
  for (std::size_t i = 0; i < s.sphere_count(); ++i) {
    const auto& p = s.sphere_position[i];
    ASSERT_TRUE(p.x >= o.offset.x && p.x <= o.offset.x + edge) << i;
    ASSERT_TRUE(p.y >= o.offset.y && p.y < o.offset.y + edge) << i;
    ASSERT_TRUE(p.z >= o.offset.z && p.z <= o.offset.z + edge) << i;
    ASSERT_TRUE(s.sphere_radius[i] >= 0.5 && s.sphere_radius[i] <= 1.0) << i;
  }
}

TEST_F(Generate, UniformSceneHasTheTargetDensity) {
  GenerateOptions o;
  o.count = std::uint64_t(1) << 14;
  o.seed = 2024;
  Scene s = cg::generate_scene(o);
  double per_body = double(count_pairs(s)) / double(o.count);
  EXPECT_NEAR(per_body, 0.4, 0.4 * 0.15);
}

TEST_F(Generate, PolydisperseSceneHasTheTargetDensity) {
  GenerateOptions o;
  o.kind = "polydisperse";
  o.count = 4096;
  o.radius_low = 0.1;
  o.radius_high = 1.0;
  std::uint64_t pairs = 0;
  for (std::uint64_t seed = 1; seed <= 4; ++seed) {
    o.seed = seed;
    pairs += count_pairs(cg::generate_scene(o));
  }
  double per_body = double(pairs) / double(4 * o.count);
  EXPECT_NEAR(per_body, 0.4, 0.4 * 0.15);
}

TEST_F(Generate, PolydisperseRadiiRespectBoundsAndRatio) {
  GenerateOptions o;
  o.kind = "polydisperse";
  o.count = std::uint64_t(1) << 16;
  o.radius_low = 0.002;
  o.radius_high = 2.0;  // ratio 1000 exactly: allowed
  Scene s = cg::generate_scene(o);
  auto [lo, hi] = std::minmax_element(s.sphere_radius.begin(), s.sphere_radius.end());
  EXPECT_GE(*lo, 0.002);
  EXPECT_LE(*hi, 2.0);
  EXPECT_GT(*hi / *lo, 900);               // the whole range is used
  double median = std::sqrt(0.002 * 2.0);  // log-uniform: half the radii below the geometric mean
  double below = double(
      std::count_if(s.sphere_radius.begin(), s.sphere_radius.end(), [&](double r) { return r < median; }));
  EXPECT_NEAR(below / double(o.count), 0.5, 0.01);
  double decade = double(
      std::count_if(s.sphere_radius.begin(), s.sphere_radius.end(), [&](double r) { return r < 0.02; }));
  EXPECT_NEAR(decade / double(o.count), 1.0 / 3, 0.01);  // one decade of three
}

TEST_F(Generate, PolydisperseRejectsBadRadii) {
  GenerateOptions o;
  o.kind = "polydisperse";
  o.count = 10;
  for (auto [low, high] :
       {std::pair{0.001, 1.5}, std::pair{0.0, 1.0}, std::pair{-1.0, 1.0}, std::pair{2.0, 1.0}}) {
    o.radius_low = low;
    o.radius_high = high;
    EXPECT_THROW(cg::generate_scene(o), cg::UsageError) << low << " " << high;
    EXPECT_THROW(cg::generate_scene_file(path("p.h5"), o), cg::UsageError) << low << " " << high;
  }
  EXPECT_TRUE(empty_dir());
}

TEST_F(Generate, CountOutsideTheRangeIsUsageError) {
  GenerateOptions o;
  for (std::uint64_t count : {std::uint64_t(0), cg::kMaxGenerateCount + 1}) {
    o.count = count;
    EXPECT_THROW(cg::generate_scene_file(path("g.h5"), o), cg::UsageError) << count;
    EXPECT_THROW(cg::generate_scene(o), cg::UsageError) << count;
  }
  EXPECT_TRUE(empty_dir());
  o.count = 1;
  cg::generate_scene_file(path("one.h5"), o);
  EXPECT_EQ(cg::read_scene(path("one.h5")).size(), 1u);
}

TEST_F(Generate, UnknownKindAndBadDensityAreUsageErrors) {
  GenerateOptions o;
  o.kind = "lattice";
  EXPECT_THROW(cg::generate_scene(o), cg::UsageError);
  o.kind = "uniform";
  o.contacts_per_body = -1;
  EXPECT_THROW(cg::generate_scene(o), cg::UsageError);
  o.contacts_per_body = 0.4;
  o.offset.y = INFINITY;
  EXPECT_THROW(cg::generate_scene(o), cg::UsageError);
}

// ---- two-size scenes (bimodal, intruders) ---------------------------------------------------------

TEST_F(Generate, LargeBodiesAreCountedAndSpreadEvenly) {
  for (std::uint64_t n : {std::uint64_t(1), std::uint64_t(7), std::uint64_t(1000), std::uint64_t(65537)})
    for (std::uint64_t k : {std::uint64_t(0), std::uint64_t(1), std::uint64_t(3), n / 2, n}) {
      if (k > n) continue;
      std::uint64_t large = 0, first = n;
      for (std::uint64_t i = 0; i < n; ++i)
        if (cg::generated_is_large(i, k, n)) {
          ++large;
          first = std::min(first, i);
        }
      EXPECT_EQ(large, k) << n << " " << k;
      if (k > 0) {
        EXPECT_LT(first, (n + k - 1) / k) << n << " " << k;  // one in each run of n / k ids
      }
    }
}

TEST_F(Generate, BimodalHasTheLargeShareOfTheVolume) {
  GenerateOptions o;
  o.kind = "bimodal";
  o.count = 1u << 16;
  o.radius_low = 0.25;
  o.radius_high = 1.0;  // 1:4, 114 large bodies
  o.large_fraction = 0.1;
  Scene s = cg::generate_scene(o);
  double v_large = 0, v_all = 0;
  std::uint64_t large = 0;
  for (double r : s.sphere_radius) {
    ASSERT_TRUE(r == 0.25 || r == 1.0) << r;
    v_all += r * r * r;
    if (r == 1.0) v_large += r * r * r, ++large;
  }
  EXPECT_EQ(large, cg::generated_large(o));
  EXPECT_NEAR(v_large / v_all, 0.1, 0.001);  // the count is rounded to whole bodies
  EXPECT_EQ(std::get<std::int64_t>(s.attributes.at("large")), std::int64_t(large));
  EXPECT_EQ(std::get<double>(s.attributes.at("large_fraction")), 0.1);
  o.large_fraction = 0;
  EXPECT_EQ(cg::generated_large(o), 0u);
  o.large_fraction = 1;
  EXPECT_EQ(cg::generated_large(o), o.count);
}

TEST_F(Generate, BimodalSceneHasTheTargetDensity) {
  GenerateOptions o;
  o.kind = "bimodal";
  o.count = 4096;
  o.radius_low = 0.25;
  o.radius_high = 1.0;
  o.large_fraction = 0.5;  // 1.5 % of the bodies large: most contacts still among the small
  std::uint64_t pairs = 0;
  for (std::uint64_t seed = 1; seed <= 4; ++seed) {
    o.seed = seed;
    pairs += count_pairs(cg::generate_scene(o));
  }
  EXPECT_NEAR(double(pairs) / double(4 * o.count), 0.4, 0.4 * 0.15);
}

TEST_F(Generate, IntrudersKeepTheGrainsDensity) {
  GenerateOptions o;
  o.kind = "intruders";
  o.count = 8192;
  o.intruders = 3;
  o.radius_low = 0.1;
  o.radius_high = 10;  // 1:100
  Scene s = cg::generate_scene(o);
  Scene grains;
  std::uint64_t large = 0;
  for (std::size_t i = 0; i < s.sphere_count(); ++i) {
    if (s.sphere_radius[i] == 10) {
      ++large;
      continue;
    }
    ASSERT_EQ(s.sphere_radius[i], 0.1) << i;
    grains.sphere_position.push_back(s.sphere_position[i]);
    grains.sphere_radius.push_back(s.sphere_radius[i]);
  }
  EXPECT_EQ(large, 3u);
  EXPECT_EQ(std::get<std::int64_t>(s.attributes.at("intruders")), 3);
  EXPECT_EQ(std::get<double>(s.attributes.at("box_edge")), cg::uniform_box_edge(8189, 0.1, 0.1, 0.4));
  EXPECT_NEAR(double(count_pairs(grains)) / double(grains.sphere_count()), 0.4, 0.4 * 0.15);
  EXPECT_GT(count_pairs(s), count_pairs(grains) + 3);  // the intruders add theirs
}

TEST_F(Generate, TwoSizeFilesMatchMemory) {
  for (const char* kind : {"bimodal", "intruders"}) {
    GenerateOptions o;
    o.kind = kind;
    o.count = (std::uint64_t(1) << 20) + 77;  // two streamed blocks
    o.radius_low = 0.001;
    o.radius_high = 1.0;  // 1:1000: allowed
    o.intruders = 5;
    cg::generate_scene_file(path(std::string(kind) + ".h5"), o);
    Scene from_file = cg::read_scene(path(std::string(kind) + ".h5"));
    expect_same_bodies(cg::generate_scene(o), from_file);
    EXPECT_EQ(from_file.attributes, cg::generate_scene(o).attributes);
  }
}

TEST_F(Generate, TwoSizeOptionsAreChecked) {
  GenerateOptions o;
  o.count = 100;
  o.kind = "bimodal";
  o.radius_low = 0.0009;
  o.radius_high = 1.0;  // 1:1111
  EXPECT_THROW(cg::generate_scene(o), cg::UsageError);
  o.radius_low = 0.001;
  o.large_fraction = 1.5;
  EXPECT_THROW(cg::generate_scene(o), cg::UsageError);
  o.large_fraction = std::nan("");
  EXPECT_THROW(cg::generate_scene(o), cg::UsageError);
  o.kind = "intruders";
  o.intruders = 101;
  EXPECT_THROW(cg::generate_scene_file(path("i.h5"), o), cg::UsageError);
  o.intruders = 0;
  EXPECT_THROW(cg::generate_scene(o), cg::UsageError);
  EXPECT_TRUE(empty_dir());
  o.intruders = 100;  // all large: the box of the large ones
  EXPECT_EQ(cg::generate_scene(o).size(), 100u);
}

// ---- builders ------------------------------------------------------------------------------------

TEST_F(Generate, ClusteredSceneIsDeterministicAndDense) {
  Scene a = cg::make_clustered_scene(4000, 5);
  expect_same_bodies(a, cg::make_clustered_scene(4000, 5));
  Scene b = cg::make_clustered_scene(4000, 6);
  EXPECT_FALSE(a.sphere_position[0] == b.sphere_position[0]);
  EXPECT_GT(double(count_pairs(a)) / 4000, 1.0);  // much denser than the 0.4 of uniform scenes
  cg::write_scene(path("c.h5"), a);
  EXPECT_EQ(cg::read_scene(path("c.h5")).size(), 4000u);  // valid against its own bounds
  EXPECT_EQ(cg::make_clustered_scene(0, 1).size(), 0u);
  EXPECT_EQ(cg::make_clustered_scene(3, 1).size(), 3u);
}

TEST_F(Generate, LatticeSceneTouchesAxisNeighbours) {
  Scene s = cg::make_lattice_scene(4, 3, 2, 2.0, 1.0, {10, 20, 30});
  ASSERT_EQ(s.size(), 24u);
  EXPECT_TRUE(s.sphere_position[1] == (cg::Vec3<double>{12, 20, 30}));
  EXPECT_TRUE(s.sphere_position[4] == (cg::Vec3<double>{10, 22, 30}));
  EXPECT_EQ(count_pairs(s), 3u * 3 * 2 + 4u * 2 * 2 + 4u * 3 * 1);
}

TEST_F(Generate, EllipsoidSceneIsValid) {
  Scene s = cg::make_ellipsoid_scene(300, 200, 11);
  EXPECT_EQ(s.sphere_count(), 300u);
  EXPECT_EQ(s.ellipsoid_count(), 200u);
  cg::write_scene(path("e.h5"), s);
  Scene back = cg::read_scene(path("e.h5"));  // unit quaternions, bounds respected
  EXPECT_EQ(back.size(), 500u);
  expect_same_bodies(s, back);
  Scene again = cg::make_ellipsoid_scene(300, 200, 11);
  EXPECT_EQ(again.ellipsoid_orientation, s.ellipsoid_orientation);
}

}  // namespace
