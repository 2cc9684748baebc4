// The CPU backend's cell sort (kernels/host/cell_sort.cpp, the default) against the entry sort
// (CONTACTGRID_HOST_ENTRIES=body-order): the same sorted keys, the same bodies in every cell, the walk's
// bodies those of each entry's body, from pack's block keys and from its cells (the cell sort's former
// path, CONTACTGRID_HOST_ENTRIES=cells-via-cells); and through the engine the same contact bytes and the same
// stats (entries, pair tests, candidates: what CPU = CUDA compares), in fp32, mixed and fp64, 1, 2 and 3
// threads, on uniform, polydisperse, clustered, one-cell, tangent, coincident and boundary scenes, a
// few huge spheres among small ones, and ellipsoids (alone and mixed with spheres).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <string>
#include <vector>

#include "backend.hpp"
#include "host/stages.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"
#include "support/host_jobs.hpp"

namespace cg::test {
namespace {

// A few huge spheres (radius 40) among many small ones: cells far wider than most bodies, so most
// cells hold many entries and a huge sphere's eight cells hold most bodies.
Spheres huge_among_small(std::size_t n, std::uint64_t seed) {
  Spheres s = random_spheres(n, 0.05, 0.3, seed);
  for (std::size_t i = 0; i < n; i += n / 4) s.r[i] = 40.0;
  s.name = "huge among small";
  return s;
}

// Most bodies in a small cube, a few spread over a box a hundred times wider: a grid of far more cells
// than bodies, which the cell sort leaves to the entry sort.
Spheres sparse(std::size_t n, std::uint64_t seed) {
  Spheres s = random_spheres(n, 0.5, 1.0, seed);
  for (std::size_t i = 0; i < n; ++i) s.p[i] = (i % 50 != 0 ? 0.05 : 100.0) * s.p[i];
  s.name = "sparse";
  return s;
}

struct SceneCase {
  Spheres s;
  bool cell_sort;  // whether the cell sort takes the scene's grid
};

std::vector<SceneCase> scene_cases() {
  Spheres far = random_spheres(10000, 0.5, 1.0, 3309).translated({1e5, -3e4, 7e3});
  far.name = "far from the origin";
  return {{random_spheres(30000, 0.5, 1.0, 3301), true},
          {random_spheres(20000, 0.05, 1.0, 3302, true), true},
          {clustered(4000, 3303), true},
          {one_cell(300, 3304), true},
          {tangent(3305), false},  // 400 small bodies in a wide box
          {coincident(3306), true},
          {on_boundaries(3307), true},
          {huge_among_small(3000, 3308), true},
          {far, true},
          {sparse(8000, 3310), false}};
}

// The sorted entries of both sorts: keys element for element, each cell's bodies as a set (the cell
// sort leaves a cell's bodies in their spatial order), and the cell sort's walk bodies from each
// entry's body; 32- and 64-bit keys, 1, 2 and 3 threads; the cell sort from pack's block keys (`keyed`,
// the default) or from its cells (the former path). Every scene's grid is sorted by hand (the wide
// ones too, which the engine leaves to the entry sort); the engine's runs check that it takes the cell
// sort where expected.
template <class Real, class Key>
void expect_cell_sort_entries(const detail::DetectJob<Real>& job, int threads, bool keyed) {
  using namespace detail::host;
  PackedBodies<Real> a, b;
  pack(job.bodies, job.plan.frame.origin, job.grid, Real(0), true, threads, a);
  pack(job.bodies, job.plan.frame.origin, job.grid, Real(0), true, threads, b, nullptr, keyed);
  ASSERT_EQ(b.block.size(), keyed ? a.spheres.size() : 0);
  ASSERT_EQ(b.cells.size(), keyed ? 0 : a.spheres.size());
  for (std::size_t i = 0; i < b.block.size(); ++i) {
    const BodyCells& c = a.cells[i];
    const std::uint32_t block =
        (c.lo[0] >> 1) + job.grid.half[0] * ((c.lo[1] >> 1) + job.grid.half[1] * (c.lo[2] >> 1));
    const std::uint32_t ctrl = a.ctrl[i];
    ASSERT_EQ(b.block[i] >> 32, i);
    ASSERT_EQ(std::uint32_t(b.block[i]), (ctrl >> 3) | block << 3 | (ctrl & 7u) << (3 + k_block_bits))
        << "body " << i;
  }
  Entries<Key> old_entries, new_entries;
  const std::uint64_t n_old = fill_entries(a, job.grid, threads, old_entries, job.plan.key_bits);
  sort_entries(old_entries, job.plan.key_bits, threads);
  BlockOrder<Real> order;
  block_sort(b, job.grid, threads, order);
  EntryBodies<Real> eb;
  const std::uint64_t n_new = cell_sort(order, job.grid, threads, new_entries, eb);
  ASSERT_EQ(n_old, n_new);
  ASSERT_EQ(new_entries.size(), n_new);
  ASSERT_EQ(eb.x.size(), n_new + k_entry_pad);
  for (std::size_t e = 0; e < n_new;) {
    std::size_t end = e + 1;
    while (end < n_new && old_entries.keys[end] == old_entries.keys[e]) ++end;
    std::vector<std::uint32_t> want(old_entries.body.begin() + std::ptrdiff_t(e),
                                    old_entries.body.begin() + std::ptrdiff_t(end));
    std::vector<std::uint32_t> got(new_entries.body.begin() + std::ptrdiff_t(e),
                                   new_entries.body.begin() + std::ptrdiff_t(end));
    std::sort(got.begin(), got.end());
    for (std::size_t k = e; k < end; ++k)
      ASSERT_EQ(new_entries.keys[k], old_entries.keys[k]) << "entry " << k;
    ASSERT_EQ(got, want) << "cell of entry " << e;
    if (end < n_new) {
      ASSERT_NE(new_entries.keys[end], new_entries.keys[e]) << "entry " << end;
    }
    e = end;
  }
  for (std::size_t e = 0; e < n_new; ++e) {
    const std::uint32_t body = new_entries.body[e];
    ASSERT_EQ(eb.x[e], a.spheres[body].x) << "entry " << e;
    ASSERT_EQ(eb.y[e], a.spheres[body].y) << "entry " << e;
    ASSERT_EQ(eb.z[e], a.spheres[body].z) << "entry " << e;
    ASSERT_EQ(eb.r[e], a.spheres[body].r) << "entry " << e;
    ASSERT_EQ(eb.ctrl[e], std::uint32_t(a.ctrl[body])) << "entry " << e;
  }
  for (std::size_t e = n_new; e < n_new + k_entry_pad; ++e) {
    ASSERT_EQ(eb.r[e], Real(0));
    ASSERT_EQ(eb.ctrl[e], 0u);
  }
}

template <class Real>
class CellSortTest : public ::testing::Test {};
using Reals = ::testing::Types<float, double>;
TYPED_TEST_SUITE(CellSortTest, Reals);

TYPED_TEST(CellSortTest, SortsToTheEntrySortsCellsAndBodies) {
  using Real = TypeParam;
  for (const SceneCase& c : scene_cases()) {
    const detail::DetectJob<Real> job = make_job<Real>(c.s);
    EXPECT_EQ(detail::host::cell_sort_wanted(job.grid, c.s.r.size(), false), c.cell_sort) << c.s.name;
    // the sorts by hand also on the grids the engine leaves to the entry sort, where the counters fit
    if (8.0 * job.grid.half[0] * job.grid.half[1] * job.grid.half[2] > double(1 << 24)) continue;
    for (int threads : {1, 2, 3}) {
      SCOPED_TRACE(c.s.name + " threads " + std::to_string(threads));
      for (bool keyed : {true, false}) {
        SCOPED_TRACE(keyed ? "block keys" : "cells");
        expect_cell_sort_entries<Real, std::uint32_t>(job, threads, keyed);
        expect_cell_sort_entries<Real, std::uint64_t>(job, threads, keyed);
      }
    }
  }
}

// The knob and the grids the cell sort takes: unset, `cells` or `cells-via-cells` it runs (pack writing
// the block keys in the first two), `body-order` and `grouped` not, nor with a report mask or a grid
// of far more cells than bodies.
TEST(CellSort, KnobAndGrids) {
  const detail::DetectJob<float> uniform = make_job<float>(random_spheres(20000, 0.5, 1.0, 3320));
  const detail::DetectJob<float> wide = make_job<float>(sparse(20000, 3321));
  EXPECT_TRUE(detail::host::cell_sort_wanted(uniform.grid, 20000, false));
  EXPECT_FALSE(detail::host::cell_sort_wanted(uniform.grid, 20000, true));
  EXPECT_FALSE(detail::host::cell_sort_wanted(wide.grid, 20000, false));
  EXPECT_TRUE(detail::host::cell_sort_packs_blocks());
  {
    const HostEntriesKnob knob("cells");
    EXPECT_TRUE(detail::host::cell_sort_wanted(uniform.grid, 20000, false));
    EXPECT_TRUE(detail::host::cell_sort_packs_blocks());
  }
  {
    const HostEntriesKnob knob("cells-via-cells");
    EXPECT_TRUE(detail::host::cell_sort_wanted(uniform.grid, 20000, false));
    EXPECT_FALSE(detail::host::cell_sort_packs_blocks());
  }
  for (const char* other : {"body-order", "grouped"}) {
    const HostEntriesKnob knob(other);
    EXPECT_FALSE(detail::host::cell_sort_wanted(uniform.grid, 20000, false)) << other;
  }
}

struct Run {
  std::string bytes;  // compare_contacts against the other run
  std::size_t contacts = 0;
  EngineStats stats;
};

template <class Real>
Run run_engine(const BodiesView& v, int threads, bool mixed, Fields fields, Contacts<Real>& out) {
  Engine<Real> e({.backend = Backend::cpu, .fields = fields, .threads = threads, .fp32_broad_phase = mixed});
  out = e.detect(v);
  Run r;
  r.contacts = out.size();
  r.stats = e.stats();
  return r;
}

void expect_same_stats(const EngineStats& a, const EngineStats& b) {
  EXPECT_EQ(a.entries, b.entries);
  EXPECT_EQ(a.pair_tests, b.pair_tests);
  EXPECT_EQ(a.candidates, b.candidates);
  EXPECT_EQ(a.contacts, b.contacts);
}

// The default through the engine on one scene against the entry sort and the cell sort's former path
// (`other`): fp32, mixed and fp64, the same contact bytes and stats.
template <class Real>
void expect_same_in_mode(const BodiesView& v, int threads, bool mixed, Fields fields, const char* other) {
  Contacts<Real> x, y;
  const Run a = run_engine(v, threads, mixed, fields, x);
  const HostEntriesKnob knob(other);
  const Run b = run_engine(v, threads, mixed, fields, y);
  EXPECT_EQ(compare_contacts(x, y), "identical") << other;
  expect_same_stats(a.stats, b.stats);
}

void expect_same_through_engine(const BodiesView& v, int threads, Fields fields) {
  for (const char* other : {"body-order", "cells-via-cells"}) {
    SCOPED_TRACE(other);
    expect_same_in_mode<float>(v, threads, false, fields, other);
    expect_same_in_mode<double>(v, threads, true, fields, other);  // mixed
    expect_same_in_mode<double>(v, threads, false, fields, other);
  }
}

TEST(CellSort, EngineGivesTheEntrySortsBytesAndStats) {
  for (const SceneCase& c : scene_cases()) {
    const BodiesView v{c.s.p, c.s.r, {}, {}};
    for (int threads : {1, 2, 3}) {
      SCOPED_TRACE(c.s.name + " threads " + std::to_string(threads));
      expect_same_through_engine(v, threads, Fields::full);
    }
  }
}

TEST(CellSort, EllipsoidScenesGiveTheEntrySortsBytesAndStats) {
  for (const ShapeScene& s :
       {make_scene("ellipsoids", 3330, 3000, 0.9, 16.0), make_scene("mixed", 3331, 4000, 0.4, 18.0)}) {
    for (int threads : {1, 2, 3}) {
      SCOPED_TRACE(s.name + " threads " + std::to_string(threads));
      expect_same_through_engine(s.view(), threads, Fields::full);
    }
  }
}

}  // namespace
}  // namespace cg::test
