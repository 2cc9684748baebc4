// The cell sort's gather of the walk's bodies (kernels/host/cell_sort.cpp): chunk by chunk of
// super-cells, the eight cell types of a chunk together (the default), against the former gather type
// after type (CONTACTGRID_HOST_CELL_BODIES=types). By hand, the sorted entries (keys and bodies) and
// the walk's bodies (x, y, z, r, control bytes, the padding) byte for byte; through the engine the
// same contact bytes and stats in fp32, mixed and fp64. Scenes above the stages' one-thread size (so
// that 2 and 3 threads split the gather), radii spread over two decades, centres on cell faces, a few
// huge spheres, one body and none.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "backend.hpp"
#include "host/stages.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"
#include "support/host_jobs.hpp"

namespace cg::test {
namespace {

// CONTACTGRID_HOST_CELL_BODIES=types for the guard's life.
class TypesGatherKnob {
 public:
  TypesGatherKnob() { ::setenv("CONTACTGRID_HOST_CELL_BODIES", "types", 1); }
  ~TypesGatherKnob() { ::unsetenv("CONTACTGRID_HOST_CELL_BODIES"); }
  TypesGatherKnob(const TypesGatherKnob&) = delete;
  TypesGatherKnob& operator=(const TypesGatherKnob&) = delete;
};

// Spheres on a lattice of cell faces: every centre coordinate a multiple of half the largest diameter,
// so that most bodies' boxes end exactly on a cell face; jittered radii, 40^3 places, 3 in 4 filled.
Spheres on_faces(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  Spheres s;
  s.name = "on cell faces";
  for (int i = 0; i < 40; ++i)
    for (int j = 0; j < 40; ++j)
      for (int k = 0; k < 40; ++k)
        if ((rng() & 3) != 0) s.add(1.0 * i, 1.0 * j, 1.0 * k, u(rng) < 0.5 ? 1.0 : 0.5 + 0.25 * u(rng));
  return s;
}

Spheres with_huge(std::size_t n, std::uint64_t seed) {
  Spheres s = random_spheres(n, 0.05, 0.3, seed);
  for (std::size_t i = 0; i < n; i += n / 5) s.r[i] = 6.0;
  s.name = "a few huge among small";
  return s;
}

std::vector<Spheres> scenes() {
  Spheres spread = random_spheres(60000, 0.02, 2.0, 3402, true);
  spread.name = "radii over two decades";
  return {random_spheres(80000, 0.5, 1.0, 3401),
          spread,
          on_faces(3403),
          with_huge(50000, 3404),
          clustered(40000, 3405),
          one_cell(300, 3406)};
}

template <class T>
bool same_bytes(const detail::host::Array<T>& a, const detail::host::Array<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

template <class Real, class Key>
void expect_same_gather(const detail::DetectJob<Real>& job, int threads) {
  using namespace detail::host;
  auto sorted = [&](Entries<Key>& e, EntryBodies<Real>& eb) {
    PackedBodies<Real> p;
    pack(job.bodies, job.plan.frame.origin, job.grid, Real(0), true, threads, p, nullptr,
         cell_sort_packs_blocks());
    BlockOrder<Real> order;
    block_sort(p, job.grid, threads, order);
    return cell_sort(order, job.grid, threads, e, eb);
  };
  Entries<Key> a, b;
  EntryBodies<Real> ea, eb;
  ASSERT_TRUE(cell_bodies_by_chunks());
  const std::uint64_t na = sorted(a, ea);
  std::uint64_t nb = 0;
  {
    const TypesGatherKnob knob;
    ASSERT_FALSE(cell_bodies_by_chunks());
    nb = sorted(b, eb);
  }
  ASSERT_EQ(na, nb);
  ASSERT_GT(na, 0u);
  EXPECT_TRUE(same_bytes(a.keys, b.keys));
  EXPECT_TRUE(same_bytes(a.body, b.body));
  EXPECT_TRUE(same_bytes(ea.x, eb.x));
  EXPECT_TRUE(same_bytes(ea.y, eb.y));
  EXPECT_TRUE(same_bytes(ea.z, eb.z));
  EXPECT_TRUE(same_bytes(ea.r, eb.r));
  EXPECT_TRUE(same_bytes(ea.ctrl, eb.ctrl));
  // and every entry's walk body is its body's packed sphere (a gather that wrote nothing, or the
  // wrong record, in both paths alike would pass the comparison above)
  PackedBodies<Real> p;
  pack(job.bodies, job.plan.frame.origin, job.grid, Real(0), true, threads, p);
  for (std::size_t e = 0; e < na; ++e) {
    const std::uint32_t i = a.body[e];
    ASSERT_LT(i, p.spheres.size()) << "entry " << e;
    ASSERT_EQ(ea.x[e], p.spheres[i].x) << "entry " << e;
    ASSERT_EQ(ea.r[e], p.spheres[i].r) << "entry " << e;
    ASSERT_EQ(ea.ctrl[e], std::uint32_t(p.ctrl[i])) << "entry " << e;
  }
}

TEST(CellBodies, ChunkGatherGivesTheTypeGathersBytes) {
  for (const Spheres& s : scenes()) {
    const detail::DetectJob<float> jf = make_job<float>(s);
    const detail::DetectJob<double> jd = make_job<double>(s);
    ASSERT_TRUE(detail::host::cell_sort_wanted(jf.grid, s.r.size(), false)) << s.name;
    for (int threads : {1, 2, 3}) {
      SCOPED_TRACE(s.name + " threads " + std::to_string(threads));
      expect_same_gather<float, std::uint32_t>(jf, threads);
      expect_same_gather<float, std::uint64_t>(jf, threads);
      expect_same_gather<double, std::uint32_t>(jd, threads);
    }
  }
}

template <class Real>
void expect_same_through_engine(const BodiesView& v, int threads, bool mixed) {
  auto run = [&](Contacts<Real>& out) {
    Engine<Real> e(
        {.backend = Backend::cpu, .fields = Fields::full, .threads = threads, .fp32_broad_phase = mixed});
    out = e.detect(v);
    return e.stats();
  };
  Contacts<Real> x, y;
  const EngineStats a = run(x);
  EngineStats b;
  {
    const TypesGatherKnob knob;
    b = run(y);
  }
  EXPECT_EQ(compare_contacts(x, y), "identical");
  EXPECT_EQ(a.entries, b.entries);
  EXPECT_EQ(a.pair_tests, b.pair_tests);
  EXPECT_EQ(a.candidates, b.candidates);
  EXPECT_EQ(a.contacts, b.contacts);
}

TEST(CellBodies, EngineGivesTheTypeGathersBytesAndStats) {
  std::vector<Spheres> all = scenes();
  Spheres one;
  one.name = "one body";
  one.add(1.5, -2.0, 0.25, 0.75);
  Spheres none;
  none.name = "no bodies";
  all.push_back(one);
  all.push_back(none);
  std::size_t with_contacts = 0;
  for (const Spheres& s : all) {
    const BodiesView v{s.p, s.r, {}, {}};
    for (int threads : {1, 2, 3}) {
      SCOPED_TRACE(s.name + " threads " + std::to_string(threads));
      expect_same_through_engine<float>(v, threads, false);
      expect_same_through_engine<double>(v, threads, true);  // mixed
      expect_same_through_engine<double>(v, threads, false);
    }
    Engine<double> e({.backend = Backend::cpu, .threads = 2});
    with_contacts += e.detect(v).size() > 0;
  }
  EXPECT_GE(with_contacts, 6u);  // the scenes have contacts to compare
}

}  // namespace
}  // namespace cg::test
