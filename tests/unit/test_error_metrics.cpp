// The exact reference library (src/reference) and the study's error metrics on hand-made contact
// sets: every count and every maximum is checked against a value worked out by hand.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

#include "reference/ellipsoid_reference.hpp"
#include "reference/error_metrics.hpp"
#include "reference/scene_reference.hpp"

namespace cg::test {
namespace {

using exact::FoundContact;
using exact::RefContact;

// A reference contact along +x: b at the origin, a at (d, 0, 0), radii ra, rb (ids 0 … 9 have r = 0.5).
RefContact ref(std::int64_t a, std::int64_t b, double distance) {
  return exact::sphere_contact(a, b, {1 + distance, 0, 0}, 0.5, {0, 0, 0}, 0.5);
}
FoundContact found_as(const RefContact& r) {
  auto d = [](const exact::LD v[3]) { return Vec3<double>{double(v[0]), double(v[1]), double(v[2])}; };
  return {r.a, r.b, double(r.distance), d(r.n), d(r.pa), d(r.pb)};
}
const std::vector<double> kRadius(10, 0.5);

TEST(ErrorMetrics, IdenticalSetsHaveNoError) {
  const std::vector<RefContact> reference{ref(0, 1, -0.1), ref(2, 3, -0.2), ref(4, 5, -1e-3)};
  std::vector<FoundContact> found;
  for (const auto& r : reference) found.push_back(found_as(r));
  const auto e = exact::compare_with_reference(found, reference, kRadius, 1e-6);
  EXPECT_EQ(e.reported, 3u);
  EXPECT_EQ(e.reference, 3u);
  EXPECT_EQ(e.matched, 3u);
  EXPECT_EQ(e.missed + e.extra + e.borderline, 0u);
  EXPECT_LT(e.max_position_rel, 1e-15);
  EXPECT_LT(e.max_normal_deg, 1e-12);
  EXPECT_LT(e.max_distance, 1e-16);
}

TEST(ErrorMetrics, MissedExtraAndBorderlineAreJudgedByTheBand) {
  const double band = 1e-6;
  // (0,1) deep: missed; (2,3) inside the band, not reported: borderline, not missed; (4,5) inside the
  // band and reported: borderline; (6,7) apart by more than the band (a wide reference holds it) and
  // reported: extra; (8,9) reported, not in the reference at all: extra.
  const std::vector<RefContact> reference{ref(0, 1, -0.1), ref(2, 3, -0.5e-6), ref(4, 5, 0.9e-6),
                                          ref(6, 7, 1e-3)};
  std::vector<FoundContact> found{found_as(reference[2]), found_as(reference[3]), found_as(ref(8, 9, -0.2))};
  const auto e = exact::compare_with_reference(found, reference, kRadius, band);
  EXPECT_EQ(e.missed, 1u);
  EXPECT_EQ(e.extra, 2u);
  EXPECT_EQ(e.borderline, 2u);
  EXPECT_EQ(e.matched, 1u);
  // The same sets with a band wider than every distance: nothing is wrong any more.
  const auto wide = exact::compare_with_reference(found, reference, kRadius, 0.15);
  EXPECT_EQ(wide.missed, 0u);
  EXPECT_EQ(wide.extra, 1u);       // (8,9) is not in the reference at all
  EXPECT_EQ(wide.borderline, 4u);  // all four reference pairs; (6,7) is matched as well
}

TEST(ErrorMetrics, PositionNormalAndDistanceErrors) {
  const std::vector<RefContact> reference{ref(0, 1, -0.1), ref(2, 3, -0.2)};
  std::vector<FoundContact> found{found_as(reference[0]), found_as(reference[1])};
  found[0].pa.y += 0.01;  // 0.01 / r(0) = 0.02
  found[1].pb.z -= 0.02;  // 0.02 / r(3) = 0.04
  const double deg = 1.0, rad = deg * std::numbers::pi / 180;
  found[1].n = {std::cos(rad), std::sin(rad), 0};
  found[0].distance += 3e-4;
  const auto e = exact::compare_with_reference(found, reference, kRadius, 1e-9);
  EXPECT_NEAR(e.max_position_rel, 0.04, 1e-12);
  EXPECT_NEAR(e.p99_position_rel, 0.04, 1e-12);  // nearest rank of two values: the larger
  EXPECT_NEAR(e.max_normal_deg, deg, 1e-9);
  EXPECT_NEAR(e.max_distance, 3e-4, 1e-12);
}

TEST(ErrorMetrics, P99IsTheNearestRank) {
  std::vector<RefContact> reference;
  std::vector<FoundContact> found;
  std::vector<double> radius;
  for (int i = 0; i < 200; ++i) {  // pair (2i, 2i+1), position error (i + 1)·1e-6 / 0.5
    reference.push_back(exact::sphere_contact(2 * i, 2 * i + 1, {0.9, 0, 0}, 0.5, {0, 0, 0}, 0.5));
    found.push_back(found_as(reference.back()));
    found.back().pb.x += (i + 1) * 1e-6;
    radius.push_back(0.5);
    radius.push_back(0.5);
  }
  const auto e = exact::compare_with_reference(found, reference, radius, 0);
  EXPECT_NEAR(e.max_position_rel, 200 * 2e-6, 1e-12);
  EXPECT_NEAR(e.p99_position_rel, 198 * 2e-6, 1e-12);  // rank ceil(0.99 · 200) = 198
}

TEST(ErrorMetrics, NanIsAnInfiniteError) {
  const std::vector<RefContact> reference{ref(0, 1, -0.1)};
  std::vector<FoundContact> found{found_as(reference[0])};
  found[0].n.x = std::numeric_limits<double>::quiet_NaN();
  found[0].pa.x = std::numeric_limits<double>::quiet_NaN();
  const auto e = exact::compare_with_reference(found, reference, kRadius, 0);
  EXPECT_TRUE(std::isinf(e.max_normal_deg));
  EXPECT_TRUE(std::isinf(e.max_position_rel));
  EXPECT_TRUE(std::isinf(e.p99_position_rel));
}

TEST(ErrorMetrics, AngleIsAccurateNearZeroAndHalfTurn) {
  EXPECT_NEAR(exact::angle_deg({1, 0, 0}, {1, 1e-12, 0}), 1e-12 * 180 / std::numbers::pi, 1e-24);
  EXPECT_NEAR(exact::angle_deg({1, 0, 0}, {-1, 1e-12, 0}), 180 - 1e-12 * 180 / std::numbers::pi, 1e-10);
  EXPECT_NEAR(exact::angle_deg({0, 0, 2}, {0, 3, 0}), 90, 1e-12);
}

// The reference library: exact centre differences (the normal of centres 1e-12 apart near 70 is
// exact, unlike a difference taken after a frame shift), the coincident convention, and the ellipsoid
// solver agreeing with the closed form on a round ellipsoid.
TEST(ExactReference, NearlyCoincidentCentresGiveTheExactNormal) {
  const Vec3<double> b{70.123456789, -3.5, 12.25};
  const Vec3<double> a{std::nextafter(b.x, 100.0), b.y, b.z};  // one ulp apart along x
  const RefContact c = exact::sphere_contact(0, 1, a, 1, b, 1);
  EXPECT_EQ(double(c.n[0]), 1.0);
  EXPECT_EQ(double(c.n[1]), 0.0);
  EXPECT_EQ(double(c.distance), double(exact::LD(a.x) - b.x - 2));
  const RefContact same = exact::sphere_contact(0, 1, b, 1, b, 0.5);
  EXPECT_EQ(double(same.n[0]), 1.0);
  EXPECT_EQ(double(same.distance), -1.5);
}

TEST(ExactReference, SceneReferenceOfRoundEllipsoidsIsTheSphereClosedForm) {
  const std::vector<Vec3<double>> p{{0, 0, 0}, {1.3, 0.4, -0.2}, {5, 5, 5}};
  const std::vector<double> r{0.8, 0.7, 0.1};
  const std::vector<Shape> shape{Shape::ellipsoid, Shape::ellipsoid, Shape::sphere};
  const std::vector<Vec3<double>> axes{{0.8, 0.8, 0.8}, {0.7, 0.7, 0.7}, {0, 0, 0}};
  const std::vector<Quat<double>> q{{0.5, 0.5, 0.5, 0.5}, {0.8, 0.6, 0, 0}, {1, 0, 0, 0}};
  const auto ell = exact::reference_contacts(BodiesView{p, r, {}, {}, shape, axes, q}, {0, 4000});
  const auto sph = exact::reference_contacts(std::span<const Vec3<double>>(p), std::span<const double>(r));
  ASSERT_EQ(ell.size(), 1u);
  ASSERT_EQ(sph.size(), 1u);
  EXPECT_NEAR(double(ell[0].distance), double(sph[0].distance), 1e-15);
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(double(ell[0].n[k]), double(sph[0].n[k]), 1e-12);
    EXPECT_NEAR(double(ell[0].pa[k]), double(sph[0].pa[k]), 1e-12);
    EXPECT_NEAR(double(ell[0].pb[k]), double(sph[0].pb[k]), 1e-12);
  }
}

TEST(ExactReference, SlackTakesInExactlyThePairsWithinIt) {
  const std::vector<Vec3<double>> p{{0, 0, 0}, {2.5, 0, 0}, {10, 0, 0}, {11.0009765625, 0, 0}};
  const std::vector<double> r{1, 1, 0.5, 0.5};  // gaps 0.5 and 2^-10
  EXPECT_EQ(exact::reference_contacts(std::span<const Vec3<double>>(p), std::span<const double>(r)).size(),
            0u);
  EXPECT_EQ(
      exact::reference_contacts(std::span<const Vec3<double>>(p), std::span<const double>(r), 0.001L).size(),
      1u);
  EXPECT_EQ(
      exact::reference_contacts(std::span<const Vec3<double>>(p), std::span<const double>(r), 0.5L).size(),
      2u);
}

}  // namespace
}  // namespace cg::test
