// The CUDA narrow stage's rejecting path (count → scan → fill), forced by the test knob
// CONTACTGRID_CUDA_CANDIDATES=cells: the pair stage proposes every pair the cell rule assigns, the
// narrow stage rejects the non-touching ones; the contacts are the CPU backend's, bit for bit, on the
// single-sort and type-pass paths. Skips, visibly, without a GPU.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <string>

#include "engine.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"

namespace cg::test {
namespace {

template <class T>
bool same_bits(const HostVector<T>& a, const HostVector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

template <class Real>
class CudaNarrowTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  }
};
using Reals = ::testing::Types<float, double>;
TYPED_TEST_SUITE(CudaNarrowTest, Reals);

TYPED_TEST(CudaNarrowTest, RejectingPathIsBitIdentical) {
  using Real = TypeParam;
  struct Unset {  // the knobs are removed even when an assertion fails
    ~Unset() {
      ::unsetenv("CONTACTGRID_CUDA_CANDIDATES");
      ::unsetenv("CONTACTGRID_CUDA_TYPE_PASSES");
    }
  } unset;
  auto masked = random_spheres(6000, 0.5, 1.0, 2201);
  std::vector<std::int64_t> ids(masked.r.size());
  std::vector<std::uint8_t> report(masked.r.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    ids[i] = std::int64_t(3 * i + 1);
    report[i] = static_cast<std::uint8_t>(((i % 3) != 0 ? kReportedBit : 0) | (i % 5 < 2 ? kPairedBit : 0));
  }
  for (const char* passes : {"0", "1"}) {
    ::setenv("CONTACTGRID_CUDA_TYPE_PASSES", passes, 1);
    for (Fields fields : {Fields::basic, Fields::full}) {
      const Spheres scenes[] = {random_spheres(20000, 0.5, 1.0, 2101), clustered(3000, 2103), tangent(2104),
                                masked};
      for (const Spheres& s : scenes) {  // the scenes of test_host_stages.cpp (non-contacts proposed)
        const bool with_mask = &s == &scenes[3];
        SCOPED_TRACE(s.name + " type passes " + passes + " " + to_string(fields));
        EngineOptions o;
        o.fields = fields;
        o.backend = Backend::cpu;
        Engine<Real> cpu(o);
        o.backend = Backend::cuda;
        Engine<Real> gpu(o);
        const BodiesView v{
            s.p, s.r, with_mask ? std::span<const std::int64_t>(ids) : std::span<const std::int64_t>{},
            with_mask ? std::span<const std::uint8_t>(report) : std::span<const std::uint8_t>{}};
        const Contacts<Real> a = cpu.detect(v);
        ::setenv("CONTACTGRID_CUDA_CANDIDATES", "cells", 1);
        const Contacts<Real> b = gpu.detect(v);
        ::unsetenv("CONTACTGRID_CUDA_CANDIDATES");
        ASSERT_EQ(a.size(), b.size());
        EXPECT_GT(gpu.stats().candidates, b.size()) << "the cell filter must propose non-contacts";
        EXPECT_EQ(cpu.stats().candidates, a.size());
        EXPECT_EQ(cpu.stats().pair_tests, gpu.stats().pair_tests);
        EXPECT_EQ(compare_contacts(b, a), "identical");
        // the same engine, default filter again: one candidate per contact
        const Contacts<Real> c = gpu.detect(v);
        EXPECT_EQ(gpu.stats().candidates, c.size());
        EXPECT_TRUE(same_bits(a.distance, c.distance));
      }
    }
  }
}

}  // namespace
}  // namespace cg::test
