// Engine::mark_resident / resident_extent (the step loop's frame and rebuild check where the resident
// rows are), one test body over both backends (CUDA cases skip, visibly, without a GPU). The oracle:
// compute_bounds of the same rows on the host (lo, hi, r_max, r_min, count bit for bit; the radius
// moments to rounding, as device_bounds) and the largest displacement computed on the host from the
// same rows, bit for bit. Seeded random rows (more than one block and one thread's share), a row
// that becomes non-finite (named by its id, the host's text), a radius that is not > 0, no rows,
// and set_resident forgetting the mark.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "backends.hpp"
#include "engine.hpp"

namespace cg::test {
namespace {

template <class Cfg>
class EngineResidentExtentTest : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(Cfg); }
};
TYPED_TEST_SUITE(EngineResidentExtentTest, BackendTypes, BackendTypeNames);

struct Rows {
  std::vector<Vec3<double>> p;
  std::vector<double> r;
  std::vector<std::int64_t> id;
};

Rows random_rows(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> x(-50, 80), rad(0.1, 0.9);
  Rows s;
  for (std::size_t i = 0; i < n; ++i) {
    s.p.push_back({x(rng), x(rng), x(rng)});
    s.r.push_back(rad(rng));
    s.id.push_back(static_cast<std::int64_t>(3 * i + 7));  // ascending, not the row index
  }
  return s;
}

double host_displacement(const Rows& now, const Rows& then) {
  double m = 0;
  for (std::size_t k = 0; k < now.p.size(); ++k) {
    const Vec3<double> d = now.p[k] - then.p[k];
    m = std::max(m, d.x * d.x + d.y * d.y + d.z * d.z);
  }
  return std::sqrt(m);
}

double component(Vec3<double> v, int axis) { return axis == 0 ? v.x : axis == 1 ? v.y : v.z; }

void expect_bounds(const Bounds& got, const Rows& s) {
  const Bounds want = compute_bounds(BodiesView{s.p, s.r, s.id, {}});
  EXPECT_EQ(got.count, want.count);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(component(got.lo, k), component(want.lo, k)) << "axis " << k;
    EXPECT_EQ(component(got.hi, k), component(want.hi, k)) << "axis " << k;
    EXPECT_NEAR(got.r_sum[k], want.r_sum[k], 1e-12 * want.r_sum[k]) << "moment " << k;
  }
  EXPECT_EQ(got.r_max, want.r_max);
  EXPECT_EQ(got.r_min, want.r_min);
}

// The text compute_bounds gives for these rows (the host's), or "" when they are valid.
std::string host_error(const Rows& s) {
  try {
    compute_bounds(BodiesView{s.p, s.r, s.id, {}});
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TYPED_TEST(EngineResidentExtentTest, BoundsAndDisplacementAreTheHostsBits) {
  for (const std::size_t n : {std::size_t(1), std::size_t(1000), std::size_t(200003)}) {
    SCOPED_TRACE("rows " + std::to_string(n));
    EngineOptions o;
    o.backend = TypeParam::backend;
    Engine<double> e(o);
    Rows s = random_rows(n, 31 + n);
    e.set_resident(BodiesView{s.p, s.r, {}, {}});
    ResidentExtent x = e.resident_extent(s.id);
    expect_bounds(x.bounds, s);
    EXPECT_EQ(x.displacement, 0) << "no mark: no displacement";

    e.mark_resident();
    const Rows marked = s;
    std::mt19937_64 rng(5 + n);
    std::uniform_real_distribution<double> d(-0.05, 0.05);
    for (int step = 0; step < 3; ++step) {
      for (Vec3<double>& p : s.p) p = p + Vec3<double>{d(rng), d(rng), d(rng)};
      s.p[n / 2] = s.p[n / 2] + Vec3<double>{0.25 * step, 0, -0.125};  // one row moves farthest
      e.write_resident(0, n, s.p.data(), s.r.data());
      x = e.resident_extent(s.id);
      expect_bounds(x.bounds, s);
      EXPECT_EQ(x.displacement, host_displacement(s, marked)) << "step " << step;
      EXPECT_GT(x.displacement, 0);
    }
    e.mark_resident();  // a new reference: nothing moved since
    EXPECT_EQ(e.resident_extent(s.id).displacement, 0);

    e.set_resident(BodiesView{s.p, s.r, {}, {}});  // other rows forget the mark
    EXPECT_EQ(e.resident_extent().displacement, 0);
  }
}

TYPED_TEST(EngineResidentExtentTest, ANonFiniteRowIsNamedByItsIdAsTheHostNamesIt) {
  const std::size_t n = 70001;
  EngineOptions o;
  o.backend = TypeParam::backend;
  Engine<float> e(o);
  Rows s = random_rows(n, 77);
  e.set_resident(BodiesView{s.p, s.r, {}, {}});
  e.mark_resident();
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  // two bad rows: the first (lowest row) is the one named, as a sequential scan names it
  s.p[60000].y = inf;
  s.p[41234].x = nan;
  e.write_resident(0, n, s.p.data(), s.r.data());
  const std::string want = host_error(s);
  ASSERT_NE(want.find("body " + std::to_string(s.id[41234]) + ": centre"), std::string::npos) << want;
  try {
    e.resident_extent(s.id);
    FAIL() << "no InputError for a NaN centre";
  } catch (const InputError& err) {
    EXPECT_EQ(std::string(err.what()), want);
  }
  // without ids: the row index
  try {
    e.resident_extent();
    FAIL() << "no InputError for a NaN centre";
  } catch (const InputError& err) {
    EXPECT_NE(std::string(err.what()).find("body 41234: centre"), std::string::npos) << err.what();
  }
  // a radius that is not > 0, rows fixed again
  s = random_rows(n, 77);
  s.r[9] = -1;
  e.write_resident(0, n, s.p.data(), s.r.data());
  try {
    e.resident_extent(s.id);
    FAIL() << "no InputError for a negative radius";
  } catch (const InputError& err) {
    EXPECT_EQ(std::string(err.what()), host_error(s));
  }
  EXPECT_THROW(e.resident_extent(std::span<const std::int64_t>(s.id.data(), n - 1)), UsageError);
}

TYPED_TEST(EngineResidentExtentTest, NoRowsHaveEmptyBounds) {
  EngineOptions o;
  o.backend = TypeParam::backend;
  Engine<double> e(o);
  Rows s;
  e.set_resident(BodiesView{s.p, s.r, {}, {}});
  e.mark_resident();
  const ResidentExtent x = e.resident_extent();
  EXPECT_EQ(x.bounds.count, 0u);
  EXPECT_EQ(x.displacement, 0);
}

}  // namespace
}  // namespace cg::test
