// The engine against the exact reference (src/reference/sphere_reference.hpp) on random and adversarial
// scenes, in both precisions and on both backends (CUDA cases skip without a GPU).
//
// Borderline band (docs/FORMAT.md §3): a pair whose exact |distance| is below
//   tol = 16 · eps(Real) · (largest local coordinate + 2 · r_max)
// may be decided either way (local coordinates are rounded to Real once); every other decision must
// equal the reference, and contact values must agree within tolerances of the same order.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "backends.hpp"
#include "core/grid.hpp"
#include "engine.hpp"
#include "reference/sphere_reference.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"

namespace cg::test {
namespace {

using exact::reference_contacts;

template <class T>
class EngineTest : public ::testing::Test {
 protected:
  using Real = typename T::Real;
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(T); }

  // cell 0: the smallest cell (the scenes' adversarial geometry is drawn for it); tuned: the default.
  Contacts<Real> run(const Spheres& s, Fields fields = Fields::basic, double cell = 0,
                     CellChoice choice = CellChoice::smallest) {
    EngineOptions o;
    o.backend = T::backend;
    o.fields = fields;
    o.cell_size = cell;
    o.cell_choice = choice;
    Engine<Real> e(o);
    Contacts<Real> c = e.detect(BodiesView{s.p, s.r, {}, {}});
    m_stats = e.stats();
    return c;
  }

  static long double tolerance(const Spheres& s) {
    double ext = 0, rmax = 0;
    Vec3<double> lo{1e300, 1e300, 1e300};
    for (std::size_t i = 0; i < s.r.size(); ++i) {
      lo = {std::min(lo.x, s.p[i].x - s.r[i]), std::min(lo.y, s.p[i].y - s.r[i]),
            std::min(lo.z, s.p[i].z - s.r[i])};
      rmax = std::max(rmax, s.r[i]);
    }
    for (std::size_t i = 0; i < s.r.size(); ++i)
      ext = std::max({ext, s.p[i].x - lo.x + s.r[i], s.p[i].y - lo.y + s.r[i], s.p[i].z - lo.z + s.r[i]});
    return 16.0L * std::numeric_limits<Real>::epsilon() * (ext + 2 * rmax);
  }

  // Same pairs as the reference outside the borderline band; values close to the reference.
  void expect_matches_reference(const Spheres& s, const Contacts<Real>& c) {
    const long double tol = tolerance(s);
    const auto ref = reference_contacts(s.p, s.r, tol);
    // sorted, unique, a < b
    for (std::size_t k = 0; k < c.size(); ++k) {
      ASSERT_LT(c.id_a[k], c.id_b[k]) << s.name << " row " << k;
      if (k) {
        ASSERT_TRUE(c.id_a[k - 1] < c.id_a[k] || (c.id_a[k - 1] == c.id_a[k] && c.id_b[k - 1] < c.id_b[k]))
            << s.name << ": not sorted/unique at row " << k;
      }
    }
    std::map<std::pair<std::int64_t, std::int64_t>, std::size_t> mine;
    for (std::size_t k = 0; k < c.size(); ++k) mine[{c.id_a[k], c.id_b[k]}] = k;
    std::size_t matched = 0;
    for (const auto& r : ref) {
      auto it = mine.find({r.a, r.b});
      if (it == mine.end()) {
        EXPECT_GT(r.distance, -tol) << s.name << ": missed pair (" << r.a << ", " << r.b << ") distance "
                                    << double(r.distance);
        continue;
      }
      ++matched;
      const std::size_t k = it->second;
      const long double vt = tol * 8 + 4 * std::numeric_limits<Real>::epsilon();
      EXPECT_NEAR(double(c.distance[k]), double(r.distance), double(vt))
          << s.name << " pair " << r.a << "," << r.b;
      if (std::fabs(double(r.pa[0] - r.pb[0])) + std::fabs(double(r.distance)) > 0 &&
          std::sqrt(double((r.pa[0] - r.pb[0]) * (r.pa[0] - r.pb[0]))) >= 0) {
        // normals are ill-defined for (nearly) coincident centres: compare only well-separated ones
        const double d = double(r.distance) + s.r[r.a] + s.r[r.b];
        if (d > 1e3 * double(tol)) {
          const Vec3<Real> n = c.normal_on_b[k];
          const double rel = double(vt) / d * 4;
          EXPECT_NEAR(double(n.x), double(r.n[0]), rel) << s.name;
          EXPECT_NEAR(double(n.y), double(r.n[1]), rel) << s.name;
          EXPECT_NEAR(double(n.z), double(r.n[2]), rel) << s.name;
          const double pt =
              double(vt) * 4 +
              4 * std::numeric_limits<Real>::epsilon() *
                  std::max({1.0, std::fabs(s.p[r.a].x), std::fabs(s.p[r.a].y), std::fabs(s.p[r.a].z)}) +
              rel * (s.r[r.a] + s.r[r.b]);
          EXPECT_NEAR(double(c.position_on_b[k].x), double(r.pb[0]), pt) << s.name;
          EXPECT_NEAR(double(c.position_on_a[k].y), double(r.pa[1]), pt) << s.name;
        }
      }
    }
    // extra pairs must be borderline: d <= ra + rb + tol was searched above with slack
    EXPECT_EQ(matched, c.size()) << s.name << ": the engine reported pairs beyond the borderline band";
  }

  EngineStats m_stats;
};
TYPED_TEST_SUITE(EngineTest, AllConfigs, ConfigNames);

TYPED_TEST(EngineTest, RandomUniformManySizes) {
  std::uint64_t seed = 11;
  for (std::size_t n : {1u, 2u, 3u, 17u, 100u, 1000u, 5000u, 20000u}) {
    auto s = random_spheres(n, 0.5, 1.0, seed++);
    this->expect_matches_reference(s, this->run(s));
  }
}

TYPED_TEST(EngineTest, RadiusRatios) {
  this->expect_matches_reference(random_spheres(4000, 0.1, 1.0, 21),
                                 this->run(random_spheres(4000, 0.1, 1.0, 21)));
  auto s = random_spheres(3000, 0.001, 1.0, 22, /*log_radii=*/true);
  this->expect_matches_reference(s, this->run(s));
}

// The default cell (tuned_cell_size) on scenes of different density and radius laws.
TYPED_TEST(EngineTest, TunedCellMatchesReference) {
  for (const Spheres& s :
       {random_spheres(20000, 0.5, 1.0, 61), random_spheres(4000, 0.1, 1.0, 62),
        random_spheres(3000, 0.001, 1.0, 63, true), clustered(3000, 64), one_cell(200, 65)})
    this->expect_matches_reference(s, this->run(s, Fields::basic, 0, CellChoice::tuned));
}

TYPED_TEST(EngineTest, Clustered) {
  auto s = clustered(3000, 31);
  this->expect_matches_reference(s, this->run(s));
}

TYPED_TEST(EngineTest, AllInOneCell) {
  auto s = one_cell(300, 41);
  auto c = this->run(s);
  EXPECT_EQ(c.size(), 300u * 299u / 2);  // every pair overlaps
  this->expect_matches_reference(s, c);
}

// Cells crowded with bodies that mostly do not touch: 1500 small spheres in a box of edge 2 and one
// sphere of radius 1 beside it (so the cell edge is the large one's): hundreds of entries per cell, more
// than the CPU pair walk flags at a time, and in each a few contacts among many pairs passed over by
// the sphere bound. fp64's broad phase in fp32 (mixed) gives fp64's contacts bit for bit.
TYPED_TEST(EngineTest, CrowdedCellsFewContacts) {
  using R = typename TestFixture::Real;
  Spheres s = random_spheres(1500, 0.02, 0.05, 71);
  double edge = 0;
  for (const auto& p : s.p) edge = std::max({edge, p.x, p.y, p.z});
  for (auto& p : s.p) p = {p.x * 2.0 / edge, p.y * 2.0 / edge, p.z * 2.0 / edge};
  s.add(4.5, 0.5, 0.5, 1.0);
  s.name = "crowded cells";
  const Contacts<R> c = this->run(s, Fields::full, 0, CellChoice::tuned);
  EXPECT_GT(c.size(), 50u);
  EXPECT_LT(c.size(), 1500u * 20u) << "most pairs in a cell must be apart";
  this->expect_matches_reference(s, c);
  if constexpr (std::is_same_v<R, double>) {
    EngineOptions o;
    o.backend = TypeParam::backend;
    o.fields = Fields::full;
    o.fp32_broad_phase = true;
    Engine<double> mixed(o);
    const Contacts<double> m = mixed.detect(BodiesView{s.p, s.r, {}, {}});
    EXPECT_EQ(test::compare_contacts(c, m), "identical");
  }
}

TYPED_TEST(EngineTest, OnCellBoundaries) {
  auto s = on_boundaries(51);
  this->expect_matches_reference(s, this->run(s, Fields::basic, 2.0));
  this->expect_matches_reference(s, this->run(s, Fields::basic, 1.0 + 1e-3));
}

TYPED_TEST(EngineTest, CoincidentCentres) {
  auto s = coincident(61);
  auto c = this->run(s, Fields::full);
  this->expect_matches_reference(s, c);
  std::size_t exact = 0;
  for (std::size_t k = 0; k < c.size(); ++k) {
    const auto a = c.id_a[k], b = c.id_b[k];
    if (s.p[a] == s.p[b]) {
      ++exact;
      EXPECT_EQ(c.normal_on_b[k].x, 1);
      EXPECT_EQ(c.normal_on_b[k].y, 0);
      EXPECT_EQ(c.normal_on_b[k].z, 0);
      EXPECT_EQ(c.lateral_friction_dir1[k].y, 1);
      EXPECT_EQ(c.lateral_friction_dir2[k].z, 1);
      // containment: distance = -(ra + rb)
      EXPECT_NEAR(double(c.distance[k]), -(s.r[a] + s.r[b]), 1e-6);
    }
  }
  EXPECT_EQ(exact, 50u);
}

TYPED_TEST(EngineTest, ExactlyTangentPairsAreContacts) {
  auto s = tangent(71);
  auto c = this->run(s);
  this->expect_matches_reference(s, c);
  std::size_t found = 0;
  for (std::size_t k = 0; k < c.size(); ++k)
    if (c.id_b[k] == c.id_a[k] + 1 && c.id_a[k] % 2 == 0) {
      ++found;
      EXPECT_EQ(c.distance[k], 0) << "pair " << c.id_a[k];
    }
  EXPECT_EQ(found, 200u);  // every built pair touches exactly
}

TYPED_TEST(EngineTest, TranslationFarFromOriginGivesSameContacts) {
  auto s = random_spheres(5000, 0.5, 1.0, 81);
  auto t = s.translated({1e6, -1e6, 1e6});
  auto c0 = this->run(s), c1 = this->run(t);
  ASSERT_EQ(c0.size(), c1.size());
  for (std::size_t k = 0; k < c0.size(); ++k) {
    ASSERT_EQ(c0.id_a[k], c1.id_a[k]);
    ASSERT_EQ(c0.id_b[k], c1.id_b[k]);
    // same local coordinates up to the rounding of (world - origin): same normals and distances
    EXPECT_NEAR(double(c0.distance[k]), double(c1.distance[k]), 1e-5);
    EXPECT_NEAR(double(c0.normal_on_b[k].x), double(c1.normal_on_b[k].x), 1e-3);
    EXPECT_NEAR(double(c0.position_on_b[k].x) + 1e6, double(c1.position_on_b[k].x), 0.07);
  }
  this->expect_matches_reference(t, c1);
}

TYPED_TEST(EngineTest, FullFieldsFollowTheContract) {
  auto s = random_spheres(2000, 0.5, 1.0, 91);
  auto basic = this->run(s, Fields::basic);
  auto c = this->run(s, Fields::full);
  EXPECT_FALSE(basic.full);
  EXPECT_TRUE(basic.local_point_a.empty());
  ASSERT_TRUE(c.full);
  ASSERT_EQ(c.size(), basic.size());
  using R = typename TypeParam::Real;
  const double eps = sizeof(R) == 4 ? 2e-5 : 1e-12;
  for (std::size_t k = 0; k < c.size(); ++k) {
    const auto n = c.normal_on_b[k], d1 = c.lateral_friction_dir1[k], d2 = c.lateral_friction_dir2[k];
    EXPECT_NEAR(double(dot(n, n)), 1, eps);
    EXPECT_NEAR(double(dot(d1, d1)), 1, eps);
    EXPECT_NEAR(double(dot(n, d1)), 0, eps);
    const auto x = cross(n, d1);
    EXPECT_NEAR(double(x.x), double(d2.x), eps);
    EXPECT_NEAR(double(x.y), double(d2.y), eps);
    EXPECT_NEAR(double(x.z), double(d2.z), eps);
    // local points: -ra·n and rb·n for spheres
    EXPECT_NEAR(double(c.local_point_a[k].x), -s.r[c.id_a[k]] * double(n.x), 1e-4);
    EXPECT_NEAR(double(c.local_point_b[k].y), s.r[c.id_b[k]] * double(n.y), 1e-4);
    // position_on_a = position_on_b + n · distance
    EXPECT_NEAR(double(c.position_on_a[k].z), double(c.position_on_b[k].z) + double(n.z * c.distance[k]),
                1e-4);
    EXPECT_EQ(c.distance[k], basic.distance[k]);
  }
}

TYPED_TEST(EngineTest, ReportMaskAndIds) {
  auto s = random_spheres(3000, 0.5, 1.0, 101);
  auto all = this->run(s);
  std::vector<std::int64_t> ids(s.r.size());
  std::vector<std::uint8_t> report(s.r.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    ids[i] = std::int64_t(10 + 3 * i);
    report[i] = (i % 3) != 0;
  }
  EngineOptions o;
  o.backend = TypeParam::backend;
  Engine<typename TypeParam::Real> e(o);
  auto c = e.detect(BodiesView{s.p, s.r, ids, report});
  std::size_t expect = 0;
  for (std::size_t k = 0; k < all.size(); ++k)
    if (all.id_a[k] % 3 != 0) {
      ASSERT_LT(expect, c.size());
      EXPECT_EQ(c.id_a[expect], 10 + 3 * all.id_a[k]);
      EXPECT_EQ(c.id_b[expect], 10 + 3 * all.id_b[k]);
      EXPECT_EQ(c.distance[expect], all.distance[k]);
      ++expect;
    }
  EXPECT_EQ(expect, c.size());
}

// The mask's two bits: a pair (a < b) is reported iff a has kReportedBit and not both have kPairedBit.
TYPED_TEST(EngineTest, PairedBitSkipsPairsFoundElsewhere) {
  auto s = random_spheres(5000, 0.5, 1.0, 113);
  const auto all = this->run(s);
  std::vector<std::uint8_t> report(s.r.size());
  for (std::size_t i = 0; i < report.size(); ++i) report[i] = static_cast<std::uint8_t>((i * 7 + i / 5) % 4);
  EngineOptions o;
  o.backend = TypeParam::backend;
  Engine<typename TypeParam::Real> e(o);
  const auto c = e.detect(BodiesView{s.p, s.r, {}, report});
  std::size_t expect = 0, skipped = 0;
  for (std::size_t k = 0; k < all.size(); ++k) {
    const std::uint8_t ra = report[static_cast<std::size_t>(all.id_a[k])],
                       rb = report[static_cast<std::size_t>(all.id_b[k])];
    if (!(ra & kReportedBit)) continue;
    if ((ra & kPairedBit) && (rb & kPairedBit)) {
      ++skipped;
      continue;
    }
    ASSERT_LT(expect, c.size());
    EXPECT_EQ(c.id_a[expect], all.id_a[k]);
    EXPECT_EQ(c.id_b[expect], all.id_b[k]);
    EXPECT_EQ(c.distance[expect], all.distance[k]);
    ++expect;
  }
  EXPECT_EQ(expect, c.size());
  EXPECT_GT(skipped, 100u);  // the scene exercises the rule
}

// Resident bodies: detect_resident = detect() on the same rows (report mask kept), also after a
// range of rows was rewritten in place (a halo refresh); read_resident returns what was written;
// ranges outside the rows are UsageErrors.
TYPED_TEST(EngineTest, ResidentBodiesRefreshInRanges) {
  using R = typename TypeParam::Real;
  auto s = random_spheres(4000, 0.5, 1.0, 107);
  std::vector<std::uint8_t> report(s.r.size());
  for (std::size_t i = 0; i < report.size(); ++i) report[i] = (i % 4) != 1;
  EngineOptions o;
  o.backend = TypeParam::backend;
  Engine<R> e(o), plain(o);
  e.set_resident(BodiesView{s.p, s.r, {}, report});
  EXPECT_EQ(e.resident_size(), s.r.size());
  auto expect_same = [&] {
    const Contacts<R> c = plain.detect(BodiesView{s.p, s.r, {}, report});
    ASSERT_GT(c.size(), 0u);
    EXPECT_EQ(e.detect_resident(), c.size());
    const Contacts<R>& r = e.resident_contacts();  // CUDA: downloaded here
    EXPECT_EQ(test::compare_contacts(r, c), "identical");
  };
  expect_same();
  // rows 1000 … 1999 move (and shrink) on the host and are written back; the rest stay resident
  std::vector<Vec3<double>> p(1000);
  std::vector<double> r(1000);
  for (std::size_t i = 0; i < 1000; ++i) {
    s.p[1000 + i] = {s.p[1000 + i].x + 0.37, s.p[1000 + i].y, s.p[1000 + i].z - 0.21};
    s.r[1000 + i] *= 0.9;
  }
  e.write_resident(1000, 1000, s.p.data() + 1000, s.r.data() + 1000);
  e.read_resident(1000, 1000, p.data(), r.data());
  for (std::size_t i = 0; i < 1000; ++i) {
    ASSERT_TRUE(p[i] == s.p[1000 + i]) << i;
    ASSERT_EQ(r[i], s.r[1000 + i]) << i;
  }
  expect_same();
  // after another detection the CUDA workspace holding the resident contacts is gone: refused, not stale
  e.detect_resident();
  e.detect(BodiesView{s.p, s.r, {}, {}});
  if (TypeParam::backend == Backend::cuda) {
    EXPECT_THROW(e.resident_contacts(), UsageError);
  } else {
    EXPECT_GT(e.resident_contacts().size(), 0u);
  }
  EXPECT_THROW(e.write_resident(3999, 2, p.data(), r.data()), UsageError);
  EXPECT_THROW(e.read_resident(4001, 0, p.data(), r.data()), UsageError);
  e.read_resident(4000, 0, p.data(), r.data());  // empty range at the end: fine
}

// The cell edge is a speed knob only: the contacts (every bit) do not depend on it, because the broad
// phase is conservative and the narrow phase works in the frame's coordinates.
TYPED_TEST(EngineTest, CellSizeChangesSpeedNotContacts) {
  auto s = random_spheres(8000, 0.5, 1.0, 111);
  const auto ref = this->run(s, Fields::full);
  for (double cell : {-1.0, 2.5, 3.0, 5.0, 9.0}) {  // -1: the tuned default
    const auto c =
        cell < 0 ? this->run(s, Fields::full, 0, CellChoice::tuned) : this->run(s, Fields::full, cell);
    ASSERT_EQ(c.size(), ref.size()) << "cell " << cell;
    ASSERT_EQ(test::compare_contacts(c, ref), "identical") << "cell " << cell;
  }
}

TYPED_TEST(EngineTest, BadBodiesAreNamed) {
  Spheres s;
  s.add(0, 0, 0, 1);
  s.add(1, std::nan(""), 0, 1);
  EXPECT_THROW(
      {
        try {
          this->run(s);
        } catch (const InputError& e) {
          EXPECT_NE(std::string(e.what()).find("body 1"), std::string::npos) << e.what();
          throw;
        }
      },
      InputError);
  Spheres z;
  z.add(0, 0, 0, 1);
  z.add(1, 0, 0, 0);
  EXPECT_THROW(this->run(z), InputError);
  Spheres small;
  small.add(0, 0, 0, 1);
  EXPECT_THROW(this->run(small, Fields::basic, 1.0), UsageError);  // cell smaller than the diameter
}

// detect(bodies, bounds): the caller's compute_bounds taken as the engine's own (the Python module's
// precision "auto"): the same contacts and stats as detect(bodies); bounds of other bodies refused.
TYPED_TEST(EngineTest, DetectWithTheCallersBoundsGivesTheSameContacts) {
  using Real = typename TypeParam::Real;
  for (const Spheres& s : {random_spheres(20000, 0.5, 1.0, 3101), clustered(3000, 3102)}) {
    SCOPED_TRACE(s.name);
    EngineOptions o;
    o.backend = TypeParam::backend;
    const BodiesView v{s.p, s.r, {}, {}};
    Engine<Real> own(o), given(o);
    const Contacts<Real> a = own.detect(v);
    const Contacts<Real> b = given.detect(v, compute_bounds(v));
    EXPECT_GT(a.size(), 0u);
    EXPECT_EQ(test::compare_contacts(a, b), "identical");
    EXPECT_EQ(own.stats().pair_tests, given.stats().pair_tests);
    EXPECT_EQ(own.stats().cell_size, given.stats().cell_size);
    const BodiesView fewer{std::span(s.p).first(100), std::span(s.r).first(100), {}, {}};
    EXPECT_THROW(given.detect(fewer, compute_bounds(v)), UsageError);
  }
}

TYPED_TEST(EngineTest, EmptyInput) {
  Spheres s;
  auto c = this->run(s);
  EXPECT_EQ(c.size(), 0u);
}

}  // namespace
}  // namespace cg::test
