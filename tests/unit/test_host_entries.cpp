// The CPU backend's entries written grouped by the top digit of their key (kernels/host/entries.cpp,
// CONTACTGRID_HOST_ENTRIES=grouped) against the body-order fill (the default): the same sorted
// entries, element for element, and through the engine the same contact bytes and the same stats
// (entries, pair tests, candidates), which CPU = CUDA compares.
#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

#include "backend.hpp"
#include "host/stages.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"
#include "support/host_jobs.hpp"

namespace cg::test {
namespace {

// A flat layer: every centre at one of two heights (the key's top bits take few values).
Spheres flat_layer(std::size_t n, std::uint64_t seed) {
  Spheres s = random_spheres(n, 0.5, 1.0, seed);
  for (std::size_t i = 0; i < n; ++i) s.p[i].z = (i % 2) * 0.75;
  s.name = "flat layer";
  return s;
}

// A dense corner: most bodies in a small cube, a few spread over a box a hundred times wider (the
// grid's keys are wide, but most entries share their top digit).
Spheres dense_corner(std::size_t n, std::uint64_t seed) {
  Spheres s = random_spheres(n, 0.5, 1.0, seed);
  for (std::size_t i = 0; i < n; ++i)
    if (i % 400 != 0)
      s.p[i] = 0.05 * s.p[i];
    else
      s.p[i] = 5.0 * s.p[i];
  s.name = "dense corner";
  return s;
}

struct Filled {
  detail::host::Entries<std::uint64_t> wide;
  detail::host::Entries<std::uint32_t> narrow;
  bool grouped = false;  // the entries came grouped by their top digit
};

// pack, entries (with the sort's key bits, as the backend calls it) and sort, 64- and 32-bit keys;
// before the sort, every group holds its digit's keys in body order.
template <class Real>
Filled fill_and_sort(const detail::DetectJob<Real>& job, int threads) {
  Filled f;
  for (int w = 0; w < 2; ++w) {
    detail::host::PackedBodies<Real> bodies;
    detail::host::pack(job.bodies, job.plan.frame.origin, job.grid, Real(0), true, threads, bodies);
    auto check_and_sort = [&](auto& e) {
      detail::host::fill_entries(bodies, job.grid, threads, e, job.plan.key_bits);
      f.grouped = !e.digit_start.empty();
      if (f.grouped) {
        EXPECT_EQ(e.digit_start.back(), e.size());
        for (std::size_t d = 0; d + 1 < e.digit_start.size(); ++d)
          for (std::size_t k = e.digit_start[d]; k < e.digit_start[d + 1]; ++k) {
            ASSERT_EQ(std::size_t(e.keys[k] >> e.digit_shift), d) << "entry " << k;
            if (k > e.digit_start[d]) {
              ASSERT_LE(e.body[k - 1], e.body[k]) << "entry " << k;
            }
          }
      }
      detail::host::sort_entries(e, job.plan.key_bits, threads);
      EXPECT_TRUE(e.digit_start.empty());
    };
    if (w == 0)
      check_and_sort(f.wide);
    else
      check_and_sort(f.narrow);
  }
  return f;
}

template <class Key>
void expect_same_entries(const detail::host::Entries<Key>& a, const detail::host::Entries<Key>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t k = 0; k < a.size(); ++k) {
    ASSERT_EQ(a.keys[k], b.keys[k]) << "entry " << k;
    ASSERT_EQ(a.body[k], b.body[k]) << "entry " << k;
  }
}

template <class Real>
class HostEntriesTest : public ::testing::Test {};
using Reals = ::testing::Types<float, double>;
TYPED_TEST_SUITE(HostEntriesTest, Reals);

// The sorted entries of the grouped fill are those of the body-order fill, element for element, for 1
// and 3 threads, 64- and 32-bit keys; the uniform scenes (polydisperse and far from the origin too)
// take the grouped fill, a dense corner (one group would hold most entries) falls back to body order,
// a flat layer either.
TYPED_TEST(HostEntriesTest, ByDigitSortsToTheBodyOrderEntries) {
  using Real = TypeParam;
  Spheres far = random_spheres(50000, 0.5, 1.0, 3104).translated({2e4, -1e4, 3e3});
  far.name = "far from the origin";
  struct Case {
    Spheres s;
    int grouped;  // 1: the grouped fill must run, 0: the fallback must, -1: either
  };
  const Case cases[] = {{random_spheres(60000, 0.5, 1.0, 3101), 1},
                        {random_spheres(40000, 0.05, 1.0, 3102, true), 1},
                        {flat_layer(50000, 3103), -1},
                        {far, 1},
                        {dense_corner(600000, 3105), 0}};
  for (const Case& c : cases) {
    const detail::DetectJob<Real> job = make_job<Real>(c.s);
    ASSERT_GT(job.plan.key_bits, 11) << c.s.name;
    for (int threads : {1, 3}) {
      SCOPED_TRACE(c.s.name + " threads " + std::to_string(threads));
      Filled by_digit;
      {
        const HostEntriesKnob knob("grouped");
        by_digit = fill_and_sort(job, threads);
      }
      if (c.grouped >= 0) {
        EXPECT_EQ(by_digit.grouped, c.grouped == 1);
      }
      const Filled body_order = fill_and_sort(job, threads);  // the default
      EXPECT_FALSE(body_order.grouped);
      expect_same_entries(by_digit.wide, body_order.wide);
      expect_same_entries(by_digit.narrow, body_order.narrow);
      EXPECT_GE(by_digit.wide.size(), c.s.r.size());
    }
  }
}

// Through the engine: the same contact bytes and stats with either fill, fp32, mixed and fp64, 1 and 3
// threads, uniform and polydisperse radii (both take the grouped fill).
TEST(HostEntries, EngineGivesTheSameBytesAndStatsWithEitherFill) {
  for (const Spheres& s :
       {random_spheres(70000, 0.5, 1.0, 3111), random_spheres(40000, 0.05, 1.0, 3112, true)}) {
    for (int threads : {1, 3}) {
      SCOPED_TRACE(s.name + " threads " + std::to_string(threads));
      const BodiesView v{s.p, s.r, {}, {}};
      auto run = [&](auto real, bool mixed, EngineStats& stats) {
        using Real = decltype(real);
        Engine<Real> e(
            {.backend = Backend::cpu, .fields = Fields::full, .threads = threads, .fp32_broad_phase = mixed});
        Contacts<Real> c = e.detect(v);
        stats = e.stats();
        return c;
      };
      for (int mode = 0; mode < 3; ++mode) {
        SCOPED_TRACE(mode == 0 ? "fp32" : mode == 1 ? "mixed" : "fp64");
        EngineStats a, b;
        std::string same;
        std::size_t n = 0;
        if (mode == 0) {
          const Contacts<float> y = run(0.0f, false, b);  // the default: body order
          const HostEntriesKnob knob("grouped");
          const Contacts<float> x = run(0.0f, false, a);
          same = compare_contacts(x, y);
          n = x.size();
        } else {
          const Contacts<double> y = run(0.0, mode == 1, b);  // the default: body order
          const HostEntriesKnob knob("grouped");
          const Contacts<double> x = run(0.0, mode == 1, a);
          same = compare_contacts(x, y);
          n = x.size();
        }
        EXPECT_GT(n, 0u);
        EXPECT_EQ(same, "identical");
        EXPECT_EQ(a.entries, b.entries);
        EXPECT_EQ(a.pair_tests, b.pair_tests);
        EXPECT_EQ(a.candidates, b.candidates);
      }
    }
  }
}

}  // namespace
}  // namespace cg::test
