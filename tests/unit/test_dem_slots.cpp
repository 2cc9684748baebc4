// The granular dynamics' slots path (kernels/dem_slots.hpp, core/dem_slots.hpp) against the rows
// path (CONTACTGRID_DEM_PATH=rows): the same trajectories bit for bit — bodies, energies, the
// contacts with their history, the candidate lists' builds — over many steps with rebuilds,
// friction and rolling friction, walls and gravity, on each backend (CUDA skips, visibly, without a
// GPU; the CPU compares its own two paths, and a CUDA slots run is compared with the CPU's).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "backends.hpp"
#include "dem.hpp"
#include "support/contacts_equal.hpp"

namespace cg::test {
namespace {

// A lattice of spheres thrown about in a box with gravity: contacts from the first steps, pairs that
// part and meet again, and the candidate list rebuilt every few steps (a small skin).
struct SlotScene {
  DemBodies bodies;
  DemOptions options;
};
SlotScene slot_scene(Backend backend, double rolling, bool synchronized, double skin = 0.02) {
  std::mt19937_64 rng(91);
  std::uniform_real_distribution<double> u(0, 1);
  SlotScene s;
  DemBodies& b = s.bodies;
  const int side = 7;
  for (int i = 0; i < side * side * 5; ++i) {
    const double r = 0.4 + 0.1 * u(rng);
    b.position.push_back(
        {0.86 * (i % side) + 0.6, 0.86 * ((i / side) % side) + 0.6, 0.86 * (i / (side * side)) + 0.6});
    b.radius.push_back(r);
    b.velocity.push_back({3 * (u(rng) - 0.5), 3 * (u(rng) - 0.5), 3 * (u(rng) - 0.5)});
    b.angular_velocity.push_back({u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5});
  }
  b.fixed.assign(b.size(), 0);
  b.fixed[3] = 1;  // an obstacle: the pair law's fixed side
  dem::Material m;
  m.young = 1e7;
  m.restitution = 0.6;
  m.friction = 0.5;
  m.rolling_friction = rolling;
  DemOptions& o = s.options;
  o.material = m;
  o.dt = time_step_limits(b, m, 5.0).automatic;
  o.gravity = {0.3, 0, -9.81};
  o.synchronized = synchronized;
  dem::Wall floor;
  floor.kind = dem::WallKind::plane;
  floor.point = {0, 0, 0};
  floor.normal = {0, 0, 1};
  dem::Wall side_wall = floor;
  side_wall.point = {0, 0, 0};
  side_wall.normal = {1, 0, 0};
  o.walls = {floor, side_wall};
  o.engine.skin = skin;
  o.engine.backend = backend;
  o.engine.threads = 2;
  return s;
}

// A simulation made on the path `path` (the knob is read when it is made).
template <class Real>
Simulation<Real> on_path(const SlotScene& s, const char* path) {
  setenv("CONTACTGRID_DEM_PATH", path, 1);
  Simulation<Real> sim(s.bodies, s.options);
  unsetenv("CONTACTGRID_DEM_PATH");
  return sim;
}

template <class Real>
void expect_same(Simulation<Real>& want, Simulation<Real>& got, const std::string& at) {
  const DemBodies x = want.bodies(), y = got.bodies();
  ASSERT_EQ(x.size(), y.size()) << at;
  ASSERT_EQ(std::memcmp(x.position.data(), y.position.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
  ASSERT_EQ(std::memcmp(x.velocity.data(), y.velocity.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
  ASSERT_EQ(
      std::memcmp(x.angular_velocity.data(), y.angular_velocity.data(), x.size() * sizeof(Vec3<double>)), 0)
      << at;
  ASSERT_EQ(want.contact_count(), got.contact_count()) << at;
  ASSERT_GT(want.contact_count(), 0u) << at;
  const Contacts<Real> a = want.contacts();
  const Contacts<Real> b = got.contacts();
  ASSERT_EQ(a.size(), b.size()) << at;
  ASSERT_EQ(compare_contacts(b, a), "identical") << at;
  ASSERT_EQ(a.age.size(), a.size()) << at;
  ASSERT_EQ(b.age.size(), b.size()) << at;
  EXPECT_EQ(std::memcmp(a.previous_row.data(), b.previous_row.data(), a.size() * sizeof(std::int64_t)), 0)
      << at;
  EXPECT_EQ(std::memcmp(a.age.data(), b.age.data(), a.size() * sizeof(std::int64_t)), 0) << at;
  const DemEnergies ea = want.energies(), eb = got.energies();
  EXPECT_EQ(ea.kinetic, eb.kinetic) << at;
  EXPECT_EQ(ea.gravity, eb.gravity) << at;
  EXPECT_EQ(ea.elastic, eb.elastic) << at;
  EXPECT_EQ(want.engine_stats().candidate_builds, got.engine_stats().candidate_builds) << at;
  EXPECT_EQ(want.engine_stats().candidate_reuses, got.engine_stats().candidate_reuses) << at;
  EXPECT_EQ(want.engine_stats().cell_size, got.engine_stats().cell_size) << at;
}

// What the run went through: rebuilds, and contacts carried across steps (history active).
template <class Real>
void expect_exercised(Simulation<Real>& sim, const std::string& at, bool reuses = true) {
  EXPECT_GT(sim.engine_stats().candidate_builds, 3u) << at;
  if (reuses)
    EXPECT_GT(sim.engine_stats().candidate_reuses, 3u) << at;
  else
    EXPECT_EQ(sim.engine_stats().candidate_reuses, 0u) << at;
  const Contacts<Real>& c = sim.contacts();
  std::size_t carried = 0;
  for (std::size_t k = 0; k < c.size(); ++k) carried += c.previous_row[k] >= 0;
  EXPECT_GT(carried, 0u) << at;
}

// rows against slots on one backend: every step for a while (rebuild steps included), then blocks.
template <class Real>
void slots_equal_rows(Backend backend, double rolling, bool synchronized, double skin = 0.02) {
  const SlotScene s = slot_scene(backend, rolling, synchronized, skin);
  Simulation<Real> rows = on_path<Real>(s, "rows");
  Simulation<Real> slots = on_path<Real>(s, "slots");
  const std::string name = std::string(std::is_same_v<Real, float> ? "fp32" : "fp64") + " rolling " +
                           std::to_string(rolling) + (synchronized ? "" : " verlet") + " skin " +
                           std::to_string(skin);
  expect_same(rows, slots, name + " start");
  for (int k = 0; k < 40; ++k) {
    rows.run(1);
    slots.run(1);
    expect_same(rows, slots, name + " step " + std::to_string(rows.steps()));
    if (::testing::Test::HasFatalFailure()) return;
  }
  for (int block = 0; block < 6; ++block) {
    rows.run(30);
    slots.run(30);
    expect_same(rows, slots, name + " step " + std::to_string(rows.steps()));
    if (::testing::Test::HasFatalFailure()) return;
  }
  expect_exercised(slots, name, skin > 1e-4);
}

template <class B>
class DemSlots : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(B); }
};
TYPED_TEST_SUITE(DemSlots, BackendTypes, BackendTypeNames);

TYPED_TEST(DemSlots, TheSlotsGiveTheRowsTrajectories) {
  slots_equal_rows<float>(TypeParam::backend, 0, true);
  slots_equal_rows<double>(TypeParam::backend, 0, true);
}

TYPED_TEST(DemSlots, RollingFrictionAndPlainVerletToo) {
  slots_equal_rows<float>(TypeParam::backend, 0.05, true);
  slots_equal_rows<double>(TypeParam::backend, 0, false);
}

// CUDA's slots against the CPU's slots (CPU = CUDA, as the rows path), with the contacts asked for at
// some steps only (the rows made from the device's slots).
TEST(DemSlotsBackends, CudaGivesTheCpuBits) {
  CG_SKIP_WITHOUT_BACKEND(OnBackend<Backend::cuda>);
  for (const bool single : {true, false}) {
    const SlotScene c = slot_scene(Backend::cpu, single ? 0.0 : 0.05, true);
    const SlotScene g = slot_scene(Backend::cuda, single ? 0.0 : 0.05, true);
    if (single) {
      Simulation<float> cpu = on_path<float>(c, "slots");
      Simulation<float> gpu = on_path<float>(g, "slots");
      for (int block = 0; block < 8; ++block) {
        cpu.run(block == 0 ? 1 : 29);
        gpu.run(block == 0 ? 1 : 29);
        expect_same(cpu, gpu, "fp32 step " + std::to_string(cpu.steps()));
        if (HasFatalFailure()) return;
      }
      expect_exercised(gpu, "fp32 cuda");
    } else {
      Simulation<double> cpu = on_path<double>(c, "slots");
      Simulation<double> gpu = on_path<double>(g, "slots");
      for (int block = 0; block < 5; ++block) {
        cpu.run(37);
        gpu.run(37);
        expect_same(cpu, gpu, "fp64 step " + std::to_string(cpu.steps()));
        if (HasFatalFailure()) return;
      }
    }
  }
}

// A skin far below a step's motion: a rebuild every step, and pairs that touched at the last step
// missing from the new list (their distance grew by more than the skin): the contacts' previous rows
// still count them (remap_slot's rows of the old list).
TYPED_TEST(DemSlots, ARebuildEveryStep) { slots_equal_rows<float>(TypeParam::backend, 0, true, 1e-7); }

// The knob: rows and slots are the two values; anything else is refused.
TEST(DemSlotsKnob, AnotherValueIsRefused) {
  const SlotScene s = slot_scene(Backend::cpu, 0, true);
  setenv("CONTACTGRID_DEM_PATH", "fused", 1);
  EXPECT_THROW(Simulation<float>(s.bodies, s.options), UsageError);
  unsetenv("CONTACTGRID_DEM_PATH");
}

}  // namespace
}  // namespace cg::test
