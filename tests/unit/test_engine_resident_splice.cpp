// Engine::splice_resident (a migration's change of the resident rows where they are), one test body
// over both backends (CUDA cases skip, visibly, without a GPU). The oracle: a second engine given the
// spliced rows whole (set_resident of the rows merged on the host) — the same rows read back bit for
// bit, the same contacts bit for bit, with a skin whose kept candidate list the splice must drop.
// Seeded random rows (more than one block), spheres and ellipsoids, ids and a report mask, changes
// at both ends, every row leaving, no rows; and the usage errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "backends.hpp"
#include "engine.hpp"

namespace cg::test {
namespace {

template <class Cfg>
class EngineResidentSpliceTest : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(Cfg); }
};
TYPED_TEST_SUITE(EngineResidentSpliceTest, BackendTypes, BackendTypeNames);

struct Rows {
  std::vector<Vec3<double>> p;
  std::vector<double> r;
  std::vector<std::int64_t> id;
  std::vector<std::uint8_t> report;
  std::vector<Shape> shape;
  std::vector<Vec3<double>> semi;
  std::vector<Quat<double>> q;
  std::size_t size() const { return r.size(); }
  void push(const Rows& o, std::size_t k, bool shapes) {
    p.push_back(o.p[k]);
    r.push_back(o.r[k]);
    id.push_back(o.id[k]);
    report.push_back(o.report[k]);
    if (shapes) {
      shape.push_back(o.shape[k]);
      semi.push_back(o.semi[k]);
      q.push_back(o.q[k]);
    }
  }
  BodiesView view(bool ids, bool reported) const {
    return BodiesView{p,
                      r,
                      ids ? std::span<const std::int64_t>(id) : std::span<const std::int64_t>{},
                      reported ? std::span<const std::uint8_t>(report) : std::span<const std::uint8_t>{},
                      shape,
                      semi,
                      q};
  }
};

// Body `id` of a box of side `side`: a sphere, or an ellipsoid (aspect up to 1:2) every third id.
Rows body_rows(const std::vector<std::int64_t>& ids, bool shapes, double side, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> x(0, side), rad(0.3, 0.8), u(-1, 1);
  Rows s;
  for (const std::int64_t id : ids) {
    const double r = rad(rng);
    s.p.push_back({x(rng), x(rng), x(rng)});
    s.id.push_back(id);
    s.report.push_back(id % 4 == 0 ? 0 : kReportedBit);
    if (shapes && id % 3 == 0) {
      s.r.push_back(r);
      s.shape.push_back(Shape::ellipsoid);
      s.semi.push_back({r, 0.75 * r, 0.5 * r});
      Quat<double> q{1 + u(rng), u(rng), u(rng), u(rng)};
      const double l = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
      s.q.push_back({q.w / l, q.x / l, q.y / l, q.z / l});
    } else {
      s.r.push_back(r);
      if (shapes) {
        s.shape.push_back(Shape::sphere);
        s.semi.push_back({r, r, r});
        s.q.push_back({1, 0, 0, 0});
      }
    }
  }
  return s;
}

void expect_same_rows(Engine<double>& got, Engine<double>& want, bool shapes) {
  const std::size_t n = want.resident_size();
  ASSERT_EQ(got.resident_size(), n);
  std::vector<Vec3<double>> p(n), p2(n), semi(n), semi2(n);
  std::vector<double> r(n), r2(n);
  std::vector<Quat<double>> q(n), q2(n);
  if (n == 0) return;
  got.read_resident(0, n, p.data(), r.data());
  want.read_resident(0, n, p2.data(), r2.data());
  for (std::size_t k = 0; k < n; ++k) {
    ASSERT_EQ(p[k].x, p2[k].x) << "row " << k;
    ASSERT_EQ(p[k].z, p2[k].z) << "row " << k;
    ASSERT_EQ(r[k], r2[k]) << "row " << k;
  }
  if (!shapes) return;
  got.read_resident_shapes(0, n, semi.data(), q.data());
  want.read_resident_shapes(0, n, semi2.data(), q2.data());
  for (std::size_t k = 0; k < n; ++k) {
    ASSERT_EQ(semi[k].y, semi2[k].y) << "row " << k;
    ASSERT_EQ(q[k].w, q2[k].w) << "row " << k;
    ASSERT_EQ(q[k].z, q2[k].z) << "row " << k;
  }
}

void expect_same_contacts(const Contacts<double>& got, const Contacts<double>& want) {
  ASSERT_EQ(got.size(), want.size());
  for (std::size_t k = 0; k < want.size(); ++k) {
    ASSERT_EQ(got.id_a[k], want.id_a[k]) << "contact " << k;
    ASSERT_EQ(got.id_b[k], want.id_b[k]) << "contact " << k;
    ASSERT_EQ(got.distance[k], want.distance[k]) << "contact " << k;
    ASSERT_EQ(got.normal_on_b[k].y, want.normal_on_b[k].y) << "contact " << k;
  }
}

TYPED_TEST(EngineResidentSpliceTest, TheSplicedRowsAreTheRowsSetWhole) {
  std::mt19937_64 rng(3131);
  for (int trial = 0; trial < 12; ++trial) {
    const bool shapes = trial % 2 == 1, ids = trial % 3 == 0, reported = trial % 4 == 2;
    const std::size_t n = trial == 0 ? 0 : trial == 1 ? 1 : trial < 4 ? 5 : 30000 + rng() % 20000;
    SCOPED_TRACE("trial " + std::to_string(trial) + ", rows " + std::to_string(n));
    // ids: a random subset of [0, 2n + 16), split into the rows held and the arrivals
    std::vector<std::int64_t> all(2 * n + 16);
    std::iota(all.begin(), all.end(), std::int64_t(0));
    std::shuffle(all.begin(), all.end(), rng);
    const std::size_t m = trial == 5 ? 0 : std::min<std::size_t>(all.size() - n, 1 + rng() % 3000);
    std::vector<std::int64_t> held(all.begin(), all.begin() + std::ptrdiff_t(n)),
        come(all.begin() + std::ptrdiff_t(n), all.begin() + std::ptrdiff_t(n + m));
    std::sort(held.begin(), held.end());
    std::sort(come.begin(), come.end());
    const double side = std::cbrt(double(n + m) / 0.4) + 1;  // about 0.4 bodies a unit volume
    const Rows old = body_rows(held, shapes, side, 7 + trial),
               arrivals = body_rows(come, shapes, side, 70 + trial);
    std::vector<std::size_t> leaving;
    for (std::size_t k = 0; k < n; ++k)
      if (trial == 3 || (trial == 4 && (k == 0 || k + 1 == n)) || rng() % 40 == 0) leaving.push_back(k);
    // the spliced rows on the host, and each arrival's place
    Rows merged;
    std::vector<std::size_t> at(m);
    for (std::size_t j = 0; j < m; ++j)
      at[j] = std::size_t(std::lower_bound(held.begin(), held.end(), come[j]) - held.begin());
    for (std::size_t k = 0, l = 0, j = 0; k <= n; ++k) {
      while (j < m && at[j] == k) merged.push(arrivals, j++, shapes);
      if (k == n) break;
      if (l < leaving.size() && leaving[l] == k) {
        ++l;
        continue;
      }
      merged.push(old, k, shapes);
    }
    EngineOptions o;
    o.backend = TypeParam::backend;
    o.skin = 0.2;
    Engine<double> got(o), want(o);
    got.set_resident(old.view(ids, reported));
    if (n > 0) got.detect_resident();  // a kept candidate list of the old rows
    got.mark_resident();
    got.splice_resident(leaving, at, arrivals.view(ids, reported));
    want.set_resident(merged.view(ids, reported));
    expect_same_rows(got, want, shapes);
    EXPECT_EQ(got.resident_extent().displacement, 0) << "the splice forgets the mark";
    if (merged.size() == 0) continue;
    const std::uint64_t builds = got.stats().candidate_builds;
    EXPECT_EQ(got.detect_resident(), want.detect_resident());
    EXPECT_EQ(got.stats().candidate_builds, builds + 1) << "the splice drops the kept list";
    EXPECT_GT(want.resident_contacts().size(), 0u);
    expect_same_contacts(got.resident_contacts(), want.resident_contacts());
  }
}

TYPED_TEST(EngineResidentSpliceTest, BadPlacesAndOtherFieldsAreUsageErrors) {
  EngineOptions o;
  o.backend = TypeParam::backend;
  Engine<double> e(o);
  const Rows old = body_rows({2, 5, 9}, false, 10, 1), one = body_rows({6}, false, 10, 2),
             shaped = body_rows({6}, true, 10, 3), none = body_rows({}, false, 10, 4);
  e.set_resident(old.view(false, false));
  const std::vector<std::size_t> unordered{2, 1}, outside{3}, place{2}, beyond{4}, two{1, 2};
  EXPECT_THROW(e.splice_resident(unordered, {}, none.view(false, false)), UsageError);
  EXPECT_THROW(e.splice_resident(outside, {}, none.view(false, false)), UsageError);
  EXPECT_THROW(e.splice_resident({}, beyond, one.view(false, false)), UsageError);
  EXPECT_THROW(e.splice_resident({}, two, one.view(false, false)), UsageError);   // a place per arrival
  EXPECT_THROW(e.splice_resident({}, place, one.view(true, false)), UsageError);  // ids the rows lack
  EXPECT_THROW(e.splice_resident({}, place, one.view(false, true)), UsageError);  // a report likewise
  EXPECT_THROW(e.splice_resident({}, place, shaped.view(false, false)), UsageError);
  EXPECT_EQ(e.resident_size(), 3u) << "a refused splice leaves the rows";
  e.splice_resident({}, place, one.view(false, false));
  EXPECT_EQ(e.resident_size(), 4u);
  const std::vector<std::size_t> all{0, 1, 2, 3};
  e.splice_resident(all, {}, none.view(false, false));
  EXPECT_EQ(e.resident_size(), 0u);
  const std::vector<std::size_t> start{0};
  e.splice_resident({}, start, shaped.view(true, false));  // no rows: the arrivals' fields are the rows'
  EXPECT_EQ(e.resident_size(), 1u);
  Vec3<double> semi;
  Quat<double> q;
  e.read_resident_shapes(0, 1, &semi, &q);
  EXPECT_EQ(semi.x, shaped.semi[0].x);
}

}  // namespace
}  // namespace cg::test
