// The CPU backend's stages one by one (kernels/host/stages.hpp), and the candidate / narrow cut: a
// pair stage with the loose cell filter hands narrow candidates that are not contacts; narrow must
// reject exactly those (count → scan → fill) and give the same contacts, bit for bit.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "backend.hpp"
#include "host/stages.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"

namespace cg::test {
namespace {

template <class Real>
detail::DetectJob<Real> make_job(const Spheres& s, Fields fields, std::span<const std::uint8_t> report = {}) {
  constexpr Precision prec = sizeof(Real) == 4 ? Precision::fp32 : Precision::fp64;
  const BodiesView v{s.p, s.r, {}, report};
  const Bounds b = compute_bounds(v);
  const Frame f = make_frame(b, 0, prec, CellChoice::tuned);
  detail::DetectJob<Real> job{v, plan_grid(b, f, prec), {}, fields};
  job.grid = detail::grid_params<Real>(job.plan);
  return job;
}

template <class Real>
void expect_same(const Contacts<Real>& a, const Contacts<Real>& b) {
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(test::compare_contacts(a, b), "identical");
}

// CONTACTGRID_HOST_PAIRS=<value> for the guard's life: `legrand` the grid's pair stage of Le Grand's
// cells, `cell-list` the cell list (opt-in, host_backend.cpp).
class HostPairs {
 public:
  explicit HostPairs(const char* value) { ::setenv("CONTACTGRID_HOST_PAIRS", value, 1); }
  ~HostPairs() { ::unsetenv("CONTACTGRID_HOST_PAIRS"); }
  HostPairs(const HostPairs&) = delete;
  HostPairs& operator=(const HostPairs&) = delete;
};

template <class Real>
class HostStagesTest : public ::testing::Test {};
using Reals = ::testing::Types<float, double>;
TYPED_TEST_SUITE(HostStagesTest, Reals);

// The cell filter proposes non-contacts; narrow rejects them and the contacts are the default's.
TYPED_TEST(HostStagesTest, NarrowRejectsLooseCandidates) {
  using Real = TypeParam;
  for (int threads : {1, 3}) {
    for (const Spheres& s :
         {random_spheres(20000, 0.5, 1.0, 2101), random_spheres(5000, 0.01, 1.0, 2102, true),
          clustered(3000, 2103), tangent(2104)}) {
      SCOPED_TRACE(s.name + " threads " + std::to_string(threads));
      const detail::DetectJob<Real> job = make_job<Real>(s, Fields::full);
      detail::HostBackend exact{threads};
      detail::HostBackend loose{threads, CandidateFilter::cells};
      Contacts<Real> a, b;
      StageTimes ta, tb;
      EngineStats sa, sb;
      {
        const HostPairs le_grand("legrand");  // the loose filter walks Le Grand's cells: the same walk
        detail::run_stages(exact, job, a, ta, sa);
      }
      detail::run_stages(loose, job, b, tb, sb);
      expect_same(a, b);
      EXPECT_EQ(sa.pair_tests, sb.pair_tests);
      EXPECT_EQ(sa.candidates, a.size());
      EXPECT_GT(sb.candidates, b.size()) << "the cell filter must propose non-contacts";
      EXPECT_GT(a.size(), 0u);
      ASSERT_EQ(ta.size(), tb.size());
      for (std::size_t i = 0; i < ta.size(); ++i) EXPECT_EQ(ta[i].name, tb[i].name);
    }
  }
}

// The same with a report mask (the masked scene of test_cuda_narrow.cpp).
TYPED_TEST(HostStagesTest, NarrowRejectsLooseCandidatesWithReportMask) {
  using Real = TypeParam;
  const Spheres s = random_spheres(6000, 0.5, 1.0, 2201);
  std::vector<std::uint8_t> report(s.r.size());
  for (std::size_t i = 0; i < report.size(); ++i)
    report[i] = static_cast<std::uint8_t>(((i % 3) != 0 ? kReportedBit : 0) | (i % 5 < 2 ? kPairedBit : 0));
  for (Fields fields : {Fields::basic, Fields::full}) {
    const detail::DetectJob<Real> job = make_job<Real>(s, fields, report);
    detail::HostBackend exact{2};
    detail::HostBackend loose{2, CandidateFilter::cells};
    Contacts<Real> a, b;
    StageTimes ta, tb;
    EngineStats sa, sb;
    detail::run_stages(exact, job, a, ta, sa);
    detail::run_stages(loose, job, b, tb, sb);
    expect_same(a, b);
    EXPECT_GT(a.size(), 0u);
    EXPECT_GT(sb.candidates, b.size());
  }
}

// The cell list (host/cell_list.cpp, cell_walk.cpp) against Le Grand's cells: the same contacts bit
// for bit in every mode and field set, for any thread count, on scenes of few and many bodies a cell,
// boundaries, coincident pairs, a line and far from the origin (the list runs: one entry a body, and
// on the random scene fewer pair tests), and on those it leaves to Le Grand's cells after its keys
// (radii over a wide range, exactly tangent pairs of unequal radii, a sparse wide scene).
TEST(HostCellList, SameContactsAsLeGrandsCells) {
  Spheres line;
  line.name = "line";
  for (int i = 0; i < 3000; ++i) line.add(0.9 * i, 0, 0, 0.5);
  Spheres sparse = random_spheres(2000, 0.5, 1.0, 2305);
  sparse.name = "sparse";
  for (std::size_t i = 0; i < sparse.p.size(); i += 2) sparse.p[i] = 1000.0 * sparse.p[i];
  Spheres far = random_spheres(20000, 0.5, 1.0, 2309).translated({1e6, -3e5, 7e4});
  far.name = "far from the origin";
  struct Case {
    Spheres s;
    bool listed;
  };
  const std::vector<Case> scenes = {{random_spheres(30000, 0.5, 1.0, 2301), true},
                                    {clustered(4000, 2303), true},
                                    {one_cell(600, 2304), true},
                                    {on_boundaries(2306), true},
                                    {coincident(2307), true},
                                    {line, true},
                                    {far, true},
                                    {random_spheres(8000, 0.01, 1.0, 2302, true), false},
                                    {tangent(2308), false},
                                    {sparse, false}};
  for (const auto& [s, listed] : scenes) {
    for (Precision prec : {Precision::fp32, Precision::fp64, Precision::mixed}) {
      for (int threads : {1, 3}) {
        SCOPED_TRACE(s.name + " " + std::string(to_string(prec)) + " threads " + std::to_string(threads));
        EngineOptions o;
        o.backend = Backend::cpu;
        o.fp32_broad_phase = prec == Precision::mixed;
        o.threads = threads;
        o.fields = threads == 1 ? Fields::basic : Fields::full;
        const BodiesView v{s.p, s.r, {}, {}};
        auto run = [&](auto real, EngineStats& stats) {
          Engine<decltype(real)> engine(o);
          Contacts<decltype(real)> c = engine.detect(v);
          stats = engine.stats();
          return c;
        };
        EngineStats list, le_grand;
        if (prec == Precision::fp32) {
          const Contacts<float> a = [&] {
            const HostPairs guard("cell-list");
            return run(0.0f, list);
          }();
          expect_same(a, run(0.0f, le_grand));
        } else {
          const Contacts<double> a = [&] {
            const HostPairs guard("cell-list");
            return run(0.0, list);
          }();
          expect_same(a, run(0.0, le_grand));
        }
        EXPECT_EQ(list.entries == s.p.size(), listed) << "entries " << list.entries;
        EXPECT_EQ(list.candidates, le_grand.candidates);
        if (s.name.rfind("random", 0) == 0 && listed) {
          EXPECT_LT(list.pair_tests, le_grand.pair_tests);
        }
      }
    }
  }
}

// CONTACTGRID_HOST_WALK=<value> for the guard's life (pairs.cpp: the float walk's flag loop, four-lane
// or AVX2 steps).
class HostWalk {
 public:
  explicit HostWalk(const char* value) { ::setenv("CONTACTGRID_HOST_WALK", value, 1); }
  ~HostWalk() { ::unsetenv("CONTACTGRID_HOST_WALK"); }
  HostWalk(const HostWalk&) = delete;
  HostWalk& operator=(const HostWalk&) = delete;
};

// The float walk's three ways (the flag loop, which the compiler vectorises from plain C++; four lanes
// a step in SSE2; eight in AVX2 where the CPU has it) give the same contact bytes and the same pair
// tests and candidates, in fp32 and mixed (fp64's decision on the enlarged floats), with the exact and
// the loose filter (every assigned pair near), 1 and 3 threads, on scenes whose cells hold one to nine
// entries (one AVX2 step an entry) and many more (clustered, one cell: steps of eight), tangent pairs,
// coincident centres and far from the origin.
TEST(HostWalk, FlagsSseAndAvx2GiveTheSameBytesAndTests) {
  if (!detail::host::walk_avx2_available())
    std::printf("note: this CPU has no AVX2: CONTACTGRID_HOST_WALK=avx2 takes the four-lane steps here\n");
  Spheres far = random_spheres(20000, 0.5, 1.0, 2409).translated({1e5, -3e4, 7e3});
  far.name = "far from the origin";
  const std::vector<Spheres> scenes = {random_spheres(30000, 0.5, 1.0, 2401),
                                       random_spheres(8000, 0.05, 1.0, 2402, true),
                                       clustered(4000, 2403),
                                       one_cell(300, 2404),
                                       tangent(2405),
                                       coincident(2406),
                                       on_boundaries(2407),
                                       far};
  struct Run {
    Contacts<double> mixed;
    Contacts<float> fp32, loose;
    std::uint64_t tests[3] = {0, 0, 0}, candidates[3] = {0, 0, 0};
  };
  for (const Spheres& s : scenes) {
    for (int threads : {1, 3}) {
      SCOPED_TRACE(s.name + " threads " + std::to_string(threads));
      const BodiesView v{s.p, s.r, {}, {}};
      const detail::DetectJob<float> job = make_job<float>(s, Fields::basic);
      std::vector<Run> runs;
      for (const char* kind : {"flags", "sse", "avx2"}) {
        SCOPED_TRACE(kind);
        const HostWalk walk(kind);
        Run r;
        Engine<double> mixed({.backend = Backend::cpu, .threads = threads, .fp32_broad_phase = true});
        r.mixed = mixed.detect(v);
        r.tests[0] = mixed.stats().pair_tests;
        r.candidates[0] = mixed.stats().candidates;
        Engine<float> fp32({.backend = Backend::cpu, .threads = threads});
        r.fp32 = fp32.detect(v);
        r.tests[1] = fp32.stats().pair_tests;
        r.candidates[1] = fp32.stats().candidates;
        detail::HostBackend loose{threads, CandidateFilter::cells};
        StageTimes times;
        EngineStats stats;
        detail::run_stages(loose, job, r.loose, times, stats);
        r.tests[2] = stats.pair_tests;
        r.candidates[2] = stats.candidates;
        runs.push_back(std::move(r));
      }
      EXPECT_GT(runs[0].mixed.size(), 0u);
      EXPECT_GT(runs[0].tests[2], 0u);
      for (std::size_t k = 1; k < runs.size(); ++k) {
        SCOPED_TRACE(k == 1 ? "sse against flags" : "avx2 against flags");
        expect_same(runs[0].mixed, runs[k].mixed);
        expect_same(runs[0].fp32, runs[k].fp32);
        expect_same(runs[0].loose, runs[k].loose);
        for (int m = 0; m < 3; ++m) {
          EXPECT_EQ(runs[0].tests[m], runs[k].tests[m]) << "mode " << m;
          EXPECT_EQ(runs[0].candidates[m], runs[k].candidates[m]) << "mode " << m;
        }
      }
    }
  }
}

// The same for scenes with ellipsoids (their bounding spheres in the walk, every assigned pair near
// under the centre cut: the AVX2 walk's queue fills on most cells), fp32 and fp64, full fields.
TEST(HostWalk, EllipsoidScenesGiveTheSameBytesAndTests) {
  for (const ShapeScene& s :
       {make_scene("ellipsoids", 2410, 3000, 0.9, 16.0), make_scene("mixed", 2411, 4000, 0.4, 18.0)}) {
    SCOPED_TRACE(s.name);
    std::vector<Contacts<float>> f32;
    std::vector<Contacts<double>> f64;
    std::vector<std::uint64_t> tests;
    for (const char* kind : {"flags", "sse", "avx2"}) {
      const HostWalk walk(kind);
      Engine<float> a({.backend = Backend::cpu, .fields = Fields::full, .threads = 2});
      f32.push_back(a.detect(s.view()));
      tests.push_back(a.stats().pair_tests);
      Engine<double> b({.backend = Backend::cpu, .fields = Fields::full, .threads = 2});
      f64.push_back(b.detect(s.view()));
      tests.push_back(b.stats().pair_tests);
    }
    EXPECT_GT(f32[0].size(), 0u);
    for (std::size_t k = 1; k < f32.size(); ++k) {
      expect_same(f32[0], f32[k]);
      expect_same(f64[0], f64[k]);
      EXPECT_EQ(tests[0], tests[2 * k]);
      EXPECT_EQ(tests[1], tests[2 * k + 1]);
    }
  }
}

// The stages by hand: the loose candidates include non-contacts (so the rejecting path has work),
// every exact candidate is among them, and narrow keeps exactly the exact ones.
TYPED_TEST(HostStagesTest, StagesByHand) {
  using Real = TypeParam;
  const Spheres s = random_spheres(6000, 0.5, 1.0, 2111);
  const detail::DetectJob<Real> job = make_job<Real>(s, Fields::basic);
  const int nt = 2;
  detail::host::PackedBodies<Real> bodies;
  detail::host::pack(job.bodies, job.plan.frame.origin, job.grid, Real(0), true, nt, bodies);
  ASSERT_EQ(bodies.spheres.size(), s.r.size());
  detail::host::Entries<std::uint64_t> entries;
  const std::uint64_t n_entries = detail::host::fill_entries(bodies, job.grid, nt, entries);
  EXPECT_GE(n_entries, s.r.size());
  EXPECT_EQ(entries.size(), n_entries);
  detail::host::sort_entries(entries, job.plan.key_bits, nt);
  for (std::size_t e = 1; e < entries.size(); ++e) ASSERT_LE(entries.keys[e - 1], entries.keys[e]);

  detail::host::CandidatePairs exact, loose;
  const auto t_exact = detail::host::find_candidates(entries, bodies, {}, job.grid.half_bits,
                                                     CandidateFilter::spheres_touch, nullptr, nt, exact);
  const auto t_loose = detail::host::find_candidates(entries, bodies, {}, job.grid.half_bits,
                                                     CandidateFilter::cells, nullptr, nt, loose);
  EXPECT_EQ(t_exact, t_loose);
  EXPECT_EQ(loose.size(), t_loose);  // every tested pair is a loose candidate
  EXPECT_GT(loose.size(), exact.size()) << "the cell filter must propose non-contacts";
  detail::host::order_candidates(exact, nt);
  detail::host::order_candidates(loose, nt);
  for (std::size_t k = 1; k < loose.size(); ++k) ASSERT_LT(loose.ab[k - 1], loose.ab[k]);
  for (std::size_t k = 0; k < loose.size(); ++k) ASSERT_LT(loose.a(k), loose.b(k));

  Contacts<Real> from_exact, from_loose;
  const NarrowBodies<Real> world{bodies.spheres.data(), reinterpret_cast<const double*>(s.p.data()),
                                 s.r.data(), job.plan.frame.origin};
  EngineStats stats;
  detail::host::narrow(exact, world, Fields::basic, nt, from_exact, stats);
  detail::host::narrow(loose, world, Fields::basic, nt, from_loose, stats);
  ASSERT_EQ(from_exact.size(), exact.size());
  expect_same(from_exact, from_loose);
  for (std::size_t k = 0; k < exact.size(); ++k) {
    ASSERT_EQ(from_exact.id_a[k], exact.a(k));
    ASSERT_EQ(from_exact.id_b[k], exact.b(k));
  }
}

// The stages' scratch pool (host/scratch_pool.hpp): a freed array's block serves the next array of
// about its size (no fresh pages to fault in), a much smaller array does not take it, and
// release_scratch_pool frees what is held.
TEST(ScratchPool, ReusesFreedBlocks) {
  using detail::host::Array;
  using detail::host::ScratchPool;
  detail::host::release_scratch_pool();
  EXPECT_EQ(ScratchPool::instance().held_bytes(), 0u);
  const float* first = nullptr;
  {
    Array<float> a(std::size_t(3) << 20);
    a.back() = 1;
    first = a.data();
  }
  EXPECT_GE(ScratchPool::instance().held_bytes(), (std::size_t(3) << 20) * sizeof(float));
  {
    Array<float> b((std::size_t(3) << 20) - 1000);
    EXPECT_EQ(b.data(), first) << "a block of about the size is reused";
    EXPECT_EQ(ScratchPool::instance().held_bytes(), 0u);
    Array<float> small(std::size_t(1) << 18);
    EXPECT_NE(small.data(), first);
  }
  detail::host::release_scratch_pool();
  EXPECT_EQ(ScratchPool::instance().held_bytes(), 0u);
}

// narrow_decide on its own: touching counts, a gap is rejected, the row is the sphere row (world
// centres 10, 12 and 12.5 on x, frame origin 10).
TEST(NarrowDecide, TouchingAcceptedGapRejected) {
  const double pos[9] = {10, 0, 0, 12, 0, 0, 12.5, 0, 0}, rad[3] = {1, 1, 1};
  const NarrowBodies<double> w{nullptr, pos, rad, {10, 0, 0}};
  NarrowFlags flags;
  const auto yes = narrow_decide(w, 0, 1, true, flags);
  EXPECT_TRUE(yes.contact);
  EXPECT_EQ(yes.row.distance, 0.0);
  EXPECT_EQ(yes.row.position_on_a.x, 11.0);
  EXPECT_FALSE(narrow_decide(w, 0, 2, true, flags).contact);
  EXPECT_EQ(flags.fp64_rows, 0u);
  EXPECT_FALSE(narrow_may_reject(CandidateFilter::spheres_touch));
  EXPECT_TRUE(narrow_may_reject(CandidateFilter::cells));
}

}  // namespace
}  // namespace cg::test
