// Engine's row lists (a halo's rows moved where the rows are: set_row_list, gather_rows,
// scatter_buffer + scatter_rows, copy_rows, rows_outside), one test body over both backends (CUDA
// cases skip, visibly, without a GPU). The oracle is the rows read and written whole through
// read_resident / write_resident on the host: packed rows bit for bit, rows scattered and copied
// where the lists say and nowhere else, the rows outside an interval as a host filter lists them;
// seeded random rows (more than one block), spheres and ellipsoids, empty lists, and the usage errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "backends.hpp"
#include "engine.hpp"

namespace cg::test {
namespace {

template <class Cfg>
class EngineRowListsTest : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(Cfg); }
};
TYPED_TEST_SUITE(EngineRowListsTest, BackendTypes, BackendTypeNames);

struct Rows {
  std::vector<Vec3<double>> p;
  std::vector<double> r;
  std::vector<Shape> shape;
  std::vector<Vec3<double>> semi;
  std::vector<Quat<double>> q;
  BodiesView view() const { return BodiesView{p, r, {}, {}, shape, semi, q}; }
};

Rows random_rows(std::size_t n, bool shapes, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> x(-50, 50), rad(0.3, 0.8), u(-1, 1);
  Rows s;
  for (std::size_t i = 0; i < n; ++i) {
    const double r = rad(rng);
    s.p.push_back({x(rng), x(rng), x(rng)});
    s.r.push_back(r);
    if (shapes) {
      s.shape.push_back(i % 3 == 0 ? Shape::ellipsoid : Shape::sphere);
      s.semi.push_back(i % 3 == 0 ? Vec3<double>{r, 0.75 * r, 0.5 * r} : Vec3<double>{r, r, r});
      Quat<double> q{1 + u(rng), u(rng), u(rng), u(rng)};
      const double l = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
      s.q.push_back(i % 3 == 0 ? Quat<double>{q.w / l, q.x / l, q.y / l, q.z / l} : Quat<double>{1, 0, 0, 0});
    }
  }
  return s;
}

// `count` distinct rows of n in a random order (a halo's order is not ascending).
std::vector<std::size_t> some_rows(std::size_t n, std::size_t count, std::uint64_t seed) {
  std::vector<std::size_t> all(n);
  for (std::size_t i = 0; i < n; ++i) all[i] = i;
  std::shuffle(all.begin(), all.end(), std::mt19937_64(seed));
  all.resize(count);
  return all;
}

// high_priority: as the step loop's boundary engine B (EngineOptions::high_priority).
template <class Real>
Engine<Real> engine_on(Backend backend, bool high_priority = false) {
  EngineOptions o;
  o.backend = backend;
  o.threads = 2;
  o.high_priority = high_priority;
  return Engine<Real>(o);
}

// The engine's rows read back whole.
template <class Real>
Rows read_back(Engine<Real>& e, bool shapes) {
  Rows s;
  const std::size_t n = e.resident_size();
  s.p.resize(n);
  s.r.resize(n);
  e.read_resident(0, n, s.p.data(), s.r.data());
  if (shapes) {
    s.semi.resize(n);
    s.q.resize(n);
    e.read_resident_shapes(0, n, s.semi.data(), s.q.data());
  }
  return s;
}

// Packed row k: position, radius, then the orientation.
void expect_packed(std::span<const std::byte> packed, const Rows& rows, const std::vector<std::size_t>& list,
                   bool orientations) {
  const std::size_t bytes = orientations ? 64 : 32;
  ASSERT_EQ(packed.size(), list.size() * bytes);
  for (std::size_t k = 0; k < list.size(); ++k) {
    const std::size_t i = list[k];
    const std::byte* row = packed.data() + k * bytes;
    ASSERT_EQ(std::memcmp(row, &rows.p[i], 24), 0) << "row " << k;
    ASSERT_EQ(std::memcmp(row + 24, &rows.r[i], 8), 0) << "row " << k;
    if (orientations) {
      ASSERT_EQ(std::memcmp(row + 32, &rows.q[i], 32), 0) << "row " << k;
    }
  }
}

void expect_same_bits(const Rows& got, const Rows& want, bool shapes) {
  ASSERT_EQ(got.r.size(), want.r.size());
  EXPECT_EQ(std::memcmp(got.p.data(), want.p.data(), want.p.size() * sizeof(Vec3<double>)), 0);
  EXPECT_EQ(std::memcmp(got.r.data(), want.r.data(), want.r.size() * sizeof(double)), 0);
  if (shapes) {
    EXPECT_EQ(std::memcmp(got.q.data(), want.q.data(), want.q.size() * sizeof(Quat<double>)), 0);
    EXPECT_EQ(std::memcmp(got.semi.data(), want.semi.data(), want.semi.size() * sizeof(Vec3<double>)), 0);
  }
}

template <class Real>
void gather_scatter_copy(Backend backend, bool shapes) {
  const std::size_t n = 3000, m = 700;  // more than one block of 256 threads
  const Rows rows = random_rows(n, shapes, 11);
  Engine<Real> a = engine_on<Real>(backend), b = engine_on<Real>(backend, true);
  a.set_resident(rows.view());
  const Rows b_rows = random_rows(n, shapes, 12);
  b.set_resident(b_rows.view());
  for (const bool orientations : shapes ? std::vector<bool>{false, true} : std::vector<bool>{false}) {
    SCOPED_TRACE(orientations ? "orientations" : "positions and radii");
    const std::vector<std::size_t> sent = some_rows(n, m, 21), into = some_rows(n, m, 22);
    a.set_row_list(0, sent);
    b.set_row_list(0, into);
    // gather: A's rows in the list's order
    const std::span<const std::byte> packed = a.gather_rows(0, orientations);
    expect_packed(packed, rows, sent, orientations);
    // scatter: B's listed rows replaced, the others kept
    const std::vector<std::byte> message(packed.begin(), packed.end());
    const std::span<std::byte> buffer = b.scatter_buffer(m, orientations);
    ASSERT_EQ(buffer.size(), message.size());
    std::copy(message.begin(), message.end(), buffer.begin());
    const Rows before = read_back(b, shapes);
    b.scatter_rows(0, orientations);
    Rows want = before;
    for (std::size_t k = 0; k < m; ++k) {
      want.p[into[k]] = rows.p[sent[k]];
      want.r[into[k]] = rows.r[sent[k]];
      if (orientations) want.q[into[k]] = rows.q[sent[k]];
    }
    expect_same_bits(read_back(b, shapes), want, shapes);
    // copy: A's list 1 into B's list 1, where the rows are
    const std::vector<std::size_t> from = some_rows(n, m / 2, 23), to = some_rows(n, m / 2, 24);
    a.set_row_list(1, from);
    b.set_row_list(1, to);
    b.copy_rows(a, 1, 1, orientations);
    for (std::size_t k = 0; k < from.size(); ++k) {
      want.p[to[k]] = rows.p[from[k]];
      want.r[to[k]] = rows.r[from[k]];
      if (orientations) want.q[to[k]] = rows.q[from[k]];
    }
    expect_same_bits(read_back(b, shapes), want, shapes);
    expect_same_bits(read_back(a, shapes), rows, shapes);  // the source is untouched
    // empty lists
    a.set_row_list(2, {});
    b.set_row_list(2, {});
    EXPECT_EQ(a.gather_rows(2, orientations).size(), 0u);
    b.scatter_buffer(0, orientations);
    b.scatter_rows(2, orientations);
    b.copy_rows(a, 2, 2, orientations);
    expect_same_bits(read_back(b, shapes), want, shapes);
  }
}

TYPED_TEST(EngineRowListsTest, GatherScatterAndCopyMoveTheListedRowsBitForBit) {
  gather_scatter_copy<double>(TypeParam::backend, false);
  gather_scatter_copy<double>(TypeParam::backend, true);
  gather_scatter_copy<float>(TypeParam::backend, true);
}

// The boundary engine's priority orders its work on the device, never its results: the same contacts
// (rows, bits) as a default engine's on the same resident rows, with and without a skin.
TYPED_TEST(EngineRowListsTest, AHighPriorityEngineFindsTheSameContacts) {
  const Rows rows = random_rows(4000, true, 41);
  for (const double skin : {0.0, 0.2}) {
    Engine<double> plain = engine_on<double>(TypeParam::backend),
                   first = engine_on<double>(TypeParam::backend, true);
    plain.set_skin(skin);
    first.set_skin(skin);
    plain.set_resident(rows.view());
    first.set_resident(rows.view());
    for (int step = 0; step < 2; ++step) {
      const std::size_t found = first.detect_resident(), want = plain.detect_resident();
      ASSERT_GT(want, 0u);
      ASSERT_EQ(found, want) << "skin " << skin << ", step " << step;
      const Contacts<double> got = first.resident_contacts(), expect = plain.resident_contacts();
      EXPECT_EQ(got.id_a, expect.id_a);
      EXPECT_EQ(got.id_b, expect.id_b);
      EXPECT_EQ(std::memcmp(got.distance.data(), expect.distance.data(), want * sizeof(double)), 0);
    }
  }
}

TYPED_TEST(EngineRowListsTest, RowsOutsideAreTheHostFiltersRows) {
  const std::size_t n = 5000;
  Rows rows = random_rows(n, false, 31);
  rows.p[17].y = 10;  // on the interval's ends: outside (the interval is open)
  rows.p[18].y = -10;
  Engine<double> e = engine_on<double>(TypeParam::backend);
  e.set_resident(rows.view());
  const double inf = std::numeric_limits<double>::infinity();
  for (const int axis : {0, 1, 2})
    for (const auto& [lo, hi] :
         std::vector<std::pair<double, double>>{{-10, 10}, {-inf, 3}, {0, inf}, {5, -5}}) {
      std::vector<std::size_t> want;
      for (std::size_t i = 0; i < n; ++i) {
        const double x = axis == 0 ? rows.p[i].x : axis == 1 ? rows.p[i].y : rows.p[i].z;
        if (!(x > lo && x < hi)) want.push_back(i);
      }
      EXPECT_EQ(e.rows_outside(axis, lo, hi), want) << "axis " << axis << " (" << lo << ", " << hi << ")";
    }
  const std::vector<std::size_t> on_ends = e.rows_outside(1, -10, 10);
  EXPECT_TRUE(std::binary_search(on_ends.begin(), on_ends.end(), std::size_t(17)));
  EXPECT_TRUE(std::binary_search(on_ends.begin(), on_ends.end(), std::size_t(18)));
  EXPECT_THROW(e.rows_outside(3, 0, 1), UsageError);
}

TYPED_TEST(EngineRowListsTest, UsageErrors) {
  const Rows rows = random_rows(100, false, 41);
  Engine<double> a = engine_on<double>(TypeParam::backend), b = engine_on<double>(TypeParam::backend);
  a.set_resident(rows.view());
  b.set_resident(rows.view());
  const std::vector<std::size_t> list{3, 1, 4};
  EXPECT_THROW(a.set_row_list(Engine<double>::kRowLists, list), UsageError);
  EXPECT_THROW(a.set_row_list(0, std::vector<std::size_t>{100}), UsageError);  // outside the rows
  EXPECT_THROW(a.gather_rows(0, false), UsageError);                           // not set
  a.set_row_list(0, list);
  EXPECT_THROW(a.gather_rows(0, true), UsageError);  // no shape rows
  b.set_row_list(0, std::vector<std::size_t>{5, 6});
  EXPECT_THROW(b.copy_rows(a, 0, 0, false), UsageError);  // other lengths
  b.scatter_buffer(1, false);
  EXPECT_THROW(b.scatter_rows(0, false), UsageError);  // the buffer holds fewer rows
  a.set_row_list(1, {});  // no rows to orient: nothing to refuse (a rank without bodies)
  EXPECT_EQ(a.gather_rows(1, true).size(), 0u);
  a.set_resident(rows.view());  // other rows: the lists go
  EXPECT_THROW(a.gather_rows(0, false), UsageError);
}

}  // namespace
}  // namespace cg::test
