// DeviceWarmUp (kernels/device_warm_up.hpp): the device made ready on a thread of its own while the
// caller works. It must start nothing where there is no GPU to warm, and a detection that runs beside
// it — on the same device, at the same time — must give the bytes it gives alone.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <random>
#include <vector>

#include "device_warm_up.hpp"
#include "support/contacts_equal.hpp"

namespace cg {
namespace {

struct Spheres {
  std::vector<Vec3<double>> position;
  std::vector<double> radius;
  BodiesView view() const { return BodiesView{position, radius, {}, {}}; }
};

Spheres random_spheres(std::size_t n, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> x(0, 40), r(0.5, 1);
  Spheres s;
  for (std::size_t i = 0; i < n; ++i) {
    s.position.push_back({x(rng), x(rng), x(rng)});
    s.radius.push_back(r(rng));
  }
  return s;
}

TEST(DeviceWarmUp, TheCpuBackendStartsNothing) {
  DeviceWarmUp warm(EngineOptions{.backend = Backend::cpu}, DeviceWarmUp::all_modes());
  warm.keep_only(Precision::fp64, false);
  EXPECT_EQ(warm.wait(), 0.0);
  EXPECT_EQ(warm.seconds(), 0.0);
  EXPECT_EQ(warm.wait(), 0.0);  // a second wait finds nothing to join
}

TEST(DeviceWarmUpCuda, DetectionsBesideItGiveTheirBytesAndTheKnobTurnsItOff) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  const Spheres scene = random_spheres(60000, 11);
  const EngineOptions options{.backend = Backend::cuda};
  Contacts<float> beside, alone;
  {
    // every mode and the ellipsoids' kernels: the thread runs while this one detects
    DeviceWarmUp warm(options, DeviceWarmUp::all_modes(), true);
    beside = Engine<float>(options).detect(scene.view());
    warm.wait();
    EXPECT_GT(warm.seconds(), 0.0);
  }
  alone = Engine<float>(options).detect(scene.view());
  ASSERT_GT(alone.size(), 1000u);
  EXPECT_TRUE(test::differing_fields(beside, alone).empty());

  ::setenv("CONTACTGRID_DEVICE_WARM_UP", "0", 1);
  DeviceWarmUp off(options, DeviceWarmUp::all_modes());
  ::unsetenv("CONTACTGRID_DEVICE_WARM_UP");
  EXPECT_EQ(off.wait(), 0.0);
  EXPECT_EQ(off.seconds(), 0.0);
}

}  // namespace
}  // namespace cg
