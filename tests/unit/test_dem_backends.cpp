// Granular dynamics (kernels/dem.hpp), the CUDA backend against the CPU backend bit for bit: a pour of
// spheres and ellipsoids, its device paths under their knobs (the body stage's indexes, the contact
// stage's terms), many bodies in runs of steps; and --stage-times on both backends (the physics cases'
// fixture, dem_physics.hpp). The CUDA cases skip, visibly, without a GPU.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "backends.hpp"
#include "core/dem_step.hpp"
#include "core/dem_sum.hpp"
#include "dem.hpp"
#include "dem_physics.hpp"
#include "support/contacts_equal.hpp"

namespace cg::test {
namespace {

using dem::Material;

TYPED_TEST_SUITE(DemPhysics, BackendTypes, BackendTypeNames);

// CPU = CUDA bit for bit: a pour of spheres and ellipsoids in a box with friction, rolling friction
// and gravity, both precisions; every body's state and every contact (with its history) after each
// block of steps. Skipped, visibly, without a GPU.
// The scene of the comparison: spheres (or spheres and ellipsoids) of radius 0.4 … 0.5 on a lattice of
// pitch 0.95 (ellipsoids: 0.8), so that some lattice neighbours start touching and the contacts (with
// their history) are exercised from the first step; random velocities, gravity, a box open at the top.
struct ComparedScene {
  DemBodies bodies;
  DemOptions options;
};
ComparedScene compared_scene(bool ellipsoids) {
  std::mt19937_64 rng(ellipsoids ? 4411 : 4412);
  std::uniform_real_distribution<double> u(0, 1);
  ComparedScene c;
  DemBodies& b = c.bodies;
  const int side = 8;
  const double pitch = ellipsoids ? 0.8 : 0.95;  // ellipsoids are slimmer (semi-axes r, 0.6r, 0.35r)
  for (int i = 0; i < side * side * 12; ++i) {
    const double r = 0.4 + 0.1 * u(rng);
    b.position.push_back(
        {pitch * (i % side) + 0.6, pitch * ((i / side) % side) + 0.6, pitch * (i / (side * side)) + 0.6});
    b.radius.push_back(r);
    b.velocity.push_back({u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5});
    if (ellipsoids) {
      const bool ell = i % 3 != 0;
      b.shape.push_back(ell ? Shape::ellipsoid : Shape::sphere);
      b.semi_axes.push_back(ell ? Vec3<double>{r, 0.6 * r, 0.35 * r} : Vec3<double>{r, r, r});
      const double cw = std::cos(0.3 * i), sw = std::sin(0.3 * i);
      b.orientation.push_back(ell ? Quat<double>{cw, sw * 0.6, 0, sw * 0.8} : Quat<double>{1, 0, 0, 0});
    }
  }
  Material m;
  m.young = 1e7;
  m.restitution = 0.6;
  m.friction = 0.4;
  m.rolling_friction = 0.02;
  DemOptions& o = c.options;
  o.material = m;
  o.dt = time_step_limits(b, m, 5.0).automatic;
  o.gravity = {0, 0, -9.81};
  o.walls = {plane({0, 0, 0}, {0, 0, 1}), plane({0, 0, 0}, {1, 0, 0}), plane({9, 0, 0}, {-1, 0, 0}),
             plane({0, 0, 0}, {0, 1, 0}), plane({0, 9, 0}, {0, -1, 0})};
  o.engine.skin = 0.05;
  return c;
}

// rolling: the scene's rolling friction, else none (the CUDA contact stage then stores no torques:
// the body stage takes them from the rows' points, core/dem_step.hpp: torques_from_points).
template <class Real>
void cpu_equals_cuda(bool ellipsoids, bool rolling = true) {
  ComparedScene scene = compared_scene(ellipsoids);
  if (!rolling) scene.options.material.rolling_friction = 0;
  const DemBodies& b = scene.bodies;
  DemOptions oc = scene.options, og = scene.options;
  oc.engine.backend = Backend::cpu;
  og.engine.backend = Backend::cuda;
  Simulation<Real> cpu(b, oc), gpu(b, og);
  for (int block = 0; block < 6; ++block) {
    cpu.run(50);
    gpu.run(50);
    const std::string at =
        std::string(ellipsoids ? "ellipsoids" : "spheres") + " step " + std::to_string(cpu.steps());
    const DemBodies x = cpu.bodies(), y = gpu.bodies();
    ASSERT_EQ(std::memcmp(x.position.data(), y.position.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
    ASSERT_EQ(std::memcmp(x.velocity.data(), y.velocity.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
    ASSERT_EQ(
        std::memcmp(x.angular_velocity.data(), y.angular_velocity.data(), x.size() * sizeof(Vec3<double>)), 0)
        << at;
    if (ellipsoids) {
      ASSERT_EQ(std::memcmp(x.orientation.data(), y.orientation.data(), x.size() * sizeof(Quat<double>)), 0)
          << at;
    }
    ASSERT_EQ(compare_contacts(gpu.contacts(), cpu.contacts()), "identical") << at;
    const DemEnergies ec = cpu.energies(), eg = gpu.energies();
    EXPECT_EQ(ec.kinetic, eg.kinetic) << at;
    EXPECT_EQ(ec.elastic, eg.elastic) << at;
    EXPECT_EQ(ec.gravity, eg.gravity) << at;
  }
}

// The compared scene keeps contacts in every block of the comparison (else a CPU = CUDA comparison of
// it would show little): run on the CPU here, so that the premise holds without a GPU.
template <class Real>
void compared_scene_touches(bool ellipsoids) {
  const ComparedScene scene = compared_scene(ellipsoids);
  DemOptions o = scene.options;
  o.engine.backend = Backend::cpu;
  Simulation<Real> cpu(scene.bodies, o);
  for (int block = 0; block < 6; ++block) {
    cpu.run(50);
    EXPECT_GT(cpu.contact_count(), ellipsoids ? 50u : 100u)
        << (ellipsoids ? "ellipsoids" : "spheres") << " step " << cpu.steps();
  }
}

TEST(DemBackends, TheComparedSceneKeepsItsContacts) {
  compared_scene_touches<double>(false);
  compared_scene_touches<float>(true);
}

TEST(DemBackends, CpuEqualsCudaBitForBit) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  cpu_equals_cuda<double>(false);
  cpu_equals_cuda<float>(false);
  cpu_equals_cuda<double>(true);
  cpu_equals_cuda<float>(true);
}

// The body stage's two indexes on the device (CONTACTGRID_DEM_SUMS=sort: a radix sort and
// lower_bound; default: counts, scans and a segmented sort), and the contact stage's two ways
// (default: every term stored; CONTACTGRID_DEM_TERMS=sums: the sums over the rows as A in the contact
// stage) give the same trajectory, bit for bit.
template <class Real>
void cuda_knob_changes_nothing(bool ellipsoids, const char* variable, const char* value,
                               bool rolling = true) {
  const ComparedScene scene = compared_scene(ellipsoids);
  DemOptions o = scene.options;
  if (!rolling) o.material.rolling_friction = 0;
  o.engine.backend = Backend::cuda;
  Simulation<Real> plain(scene.bodies, o);
  setenv(variable, value, 1);
  Simulation<Real> knob(scene.bodies, o);  // (the knob is read when a simulation starts)
  unsetenv(variable);
  for (int block = 0; block < 3; ++block) {
    plain.run(50);
    knob.run(50);
    const std::string at =
        std::string(ellipsoids ? "ellipsoids" : "spheres") + " step " + std::to_string(plain.steps());
    const DemBodies x = plain.bodies(), y = knob.bodies();
    ASSERT_EQ(std::memcmp(x.position.data(), y.position.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
    ASSERT_EQ(
        std::memcmp(x.angular_velocity.data(), y.angular_velocity.data(), x.size() * sizeof(Vec3<double>)), 0)
        << at;
    ASSERT_GT(plain.contact_count(), 0u) << at;
    const DemEnergies ec = plain.energies(), es = knob.energies();
    EXPECT_EQ(ec.elastic, es.elastic) << at;
  }
}

TEST(DemBackends, CudaSumsBySortEqualCounts) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  cuda_knob_changes_nothing<float>(false, "CONTACTGRID_DEM_SUMS", "sort");
  cuda_knob_changes_nothing<double>(true, "CONTACTGRID_DEM_SUMS", "sort");
}

TEST(DemBackends, CudaTermsByRowsEqualASums) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  cuda_knob_changes_nothing<float>(false, "CONTACTGRID_DEM_TERMS", "sums");
  cuda_knob_changes_nothing<double>(true, "CONTACTGRID_DEM_TERMS", "sums");
}

// Each body's rows as B sorted by its own device thread (default) or by CUB's segmented sort
// (CONTACTGRID_DEM_SEGMENTS=cub): the same order, the same trajectory.
TEST(DemBackends, CudaSegmentsByThreadEqualCub) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  cuda_knob_changes_nothing<float>(false, "CONTACTGRID_DEM_SEGMENTS", "cub");
  cuda_knob_changes_nothing<double>(true, "CONTACTGRID_DEM_SEGMENTS", "cub");
}

// The CUDA contact stage stores only what a later stage reads (no torques without rolling
// resistance: the body stage takes them from the rows' points; fp32 normals as detected; energies on
// a run's last step): the same trajectory and energies as every term stored (CONTACTGRID_DEM_STORE=all)
// and as the CPU's, spheres and ellipsoids, both precisions, with and without rolling resistance.
TEST(DemBackends, CudaStoredTermsOnlyEqualAllAndCpu) {
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  for (const bool rolling : {false, true}) {
    cuda_knob_changes_nothing<float>(false, "CONTACTGRID_DEM_STORE", "all", rolling);
    cuda_knob_changes_nothing<double>(false, "CONTACTGRID_DEM_STORE", "all", rolling);
    cuda_knob_changes_nothing<float>(true, "CONTACTGRID_DEM_STORE", "all", rolling);
  }
  cpu_equals_cuda<float>(false, false);
  cpu_equals_cuda<double>(false, false);
  cpu_equals_cuda<float>(true, false);
  cpu_equals_cuda<double>(true, false);
}

// More bodies and contacts than kEnergyChunk² (the energies' tree three levels deep on both backends),
// steps in runs of several lengths (CUDA: the body stage does the next step's kick_drift within a run,
// a separate pass at a run's start): CPU = CUDA bit for bit, energies too.
TEST(DemBackends, ManyBodiesInRunsCpuEqualsCuda) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0, 1);
  DemBodies b;
  const int side = 40;
  for (int i = 0; i < side * side * 2; ++i) {
    b.position.push_back(
        {0.95 * (i % side) + 0.6, 0.95 * ((i / side) % side) + 0.6, 0.95 * (i / (side * side)) + 0.5});
    b.radius.push_back(0.48 + 0.02 * u(rng));
    b.velocity.push_back({0.2 * (u(rng) - 0.5), 0.2 * (u(rng) - 0.5), 0.2 * (u(rng) - 0.5)});
  }
  Material m;
  m.young = 1e7;
  m.restitution = 0.6;
  m.friction = 0.4;
  DemOptions o;
  o.material = m;
  o.dt = time_step_limits(b, m, 5.0).automatic;
  o.gravity = {0, 0, -9.81};
  o.walls = {plane({0, 0, 0}, {0, 0, 1})};
  o.engine.skin = 0.05;
  o.engine.backend = Backend::cpu;
  Simulation<float> cpu(b, o);
  const std::size_t c = dem::kEnergyChunk;
  cpu.run(1);
  ASSERT_GT(b.size(), c * c);
  ASSERT_GT(cpu.contact_count(), c * c);  // the premise: three levels for the contacts too
  if (!cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped";
  o.engine.backend = Backend::cuda;
  Simulation<float> gpu(b, o);
  gpu.run(1);
  for (const int steps : {3, 1, 2, 5}) {
    cpu.run(std::uint64_t(steps));
    gpu.run(std::uint64_t(steps));
    const std::string at = "step " + std::to_string(cpu.steps());
    const DemBodies x = cpu.bodies(), y = gpu.bodies();
    ASSERT_EQ(std::memcmp(x.position.data(), y.position.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
    ASSERT_EQ(std::memcmp(x.velocity.data(), y.velocity.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
    ASSERT_EQ(
        std::memcmp(x.angular_velocity.data(), y.angular_velocity.data(), x.size() * sizeof(Vec3<double>)), 0)
        << at;
    const DemEnergies ec = cpu.energies(), eg = gpu.energies();
    EXPECT_EQ(ec.kinetic, eg.kinetic) << at;
    EXPECT_EQ(ec.elastic, eg.elastic) << at;
    EXPECT_EQ(ec.gravity, eg.gravity) << at;
    EXPECT_GT(ec.elastic, 0) << at;
  }
}

// --stage-times: every step's stages are timed in order, the engine's stages within detect too, and
// timing changes nothing of the trajectory.
TYPED_TEST(DemPhysics, StageTimesCoverEveryStepAndChangeNothing) {
  const ComparedScene scene = compared_scene(false);
  DemOptions o = scene.options;
  o.engine.backend = TypeParam::backend;
  Simulation<double> plain(scene.bodies, o);
  o.stage_times = true;
  Simulation<double> timed(scene.bodies, o);
  EXPECT_EQ(plain.stage_times().steps, 0u);
  plain.run(30);
  timed.run(20);
  timed.run(10);
  (void)timed.energies();
  const DemStageTimes t = timed.stage_times();
  EXPECT_EQ(t.steps, 30u);
  const std::vector<std::string> names{"kick_drift", "detect",     "contact_terms",
                                       "body_index", "body_terms", "kick"};
  ASSERT_EQ(t.step.size(), names.size());
  double total = 0;
  for (std::size_t i = 0; i < names.size(); ++i) {
    EXPECT_EQ(t.step[i].name, names[i]);
    EXPECT_GE(t.step[i].seconds, 0) << names[i];
    total += t.step[i].seconds;
  }
  EXPECT_GT(total, 0);
  EXPECT_GT(t.step[1].seconds, 0);  // detect
  EXPECT_FALSE(t.detection.empty());
  EXPECT_EQ(t.energy_calls, 1u);
  const DemBodies x = plain.bodies(), y = timed.bodies();
  EXPECT_EQ(std::memcmp(x.position.data(), y.position.data(), x.size() * sizeof(Vec3<double>)), 0);
  EXPECT_EQ(std::memcmp(x.velocity.data(), y.velocity.data(), x.size() * sizeof(Vec3<double>)), 0);
}

}  // namespace
}  // namespace cg::test
