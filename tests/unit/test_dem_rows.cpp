// A Simulation's rank interface (kernels/dem.hpp; src/simulate/resident_dem.hpp drives it under
// mpirun): a step in two halves, the rows' state out and in, and the rows set again with what they
// carry, give the trajectory of run() bit for bit on each backend (CUDA skips, visibly, without a GPU).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "backends.hpp"
#include "core/dem_sum.hpp"
#include "dem.hpp"
#include "support/contacts_equal.hpp"

namespace cg::test {
namespace {

// A box of spheres and ellipsoids falling onto a floor with friction: contacts with history from
// the first steps (the lattice's pitch is below the diameters).
struct RowsScene {
  DemBodies bodies;
  DemOptions options;
};
RowsScene rows_scene(Backend backend, bool ellipsoids) {
  std::mt19937_64 rng(ellipsoids ? 77 : 78);
  std::uniform_real_distribution<double> u(0, 1);
  RowsScene s;
  DemBodies& b = s.bodies;
  const int side = 6;
  for (int i = 0; i < side * side * 6; ++i) {
    const double r = 0.4 + 0.1 * u(rng);
    b.position.push_back(
        {0.85 * (i % side) + 0.6, 0.85 * ((i / side) % side) + 0.6, 0.85 * (i / (side * side)) + 0.6});
    b.radius.push_back(r);
    b.velocity.push_back({u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5});
    if (ellipsoids) {
      const bool ell = i % 2 == 0;
      b.shape.push_back(ell ? Shape::ellipsoid : Shape::sphere);
      b.semi_axes.push_back(ell ? Vec3<double>{r, 0.7 * r, 0.5 * r} : Vec3<double>{r, r, r});
      const double c = std::cos(0.2 * i), sn = std::sin(0.2 * i);
      b.orientation.push_back(ell ? Quat<double>{c, 0, sn, 0} : Quat<double>{1, 0, 0, 0});
    }
  }
  dem::Material m;
  m.young = 1e7;
  m.restitution = 0.5;
  m.friction = 0.5;
  m.rolling_friction = 0.02;
  DemOptions& o = s.options;
  o.material = m;
  o.dt = time_step_limits(b, m, 5.0).automatic;
  o.gravity = {0.5, 0, -9.81};
  dem::Wall floor;
  floor.kind = dem::WallKind::plane;
  floor.point = {0, 0, 0};
  floor.normal = {0, 0, 1};
  o.walls = {floor};
  o.engine.skin = 0.05;
  o.engine.backend = backend;
  o.engine.threads = 2;
  return s;
}

template <class Real>
void expect_same(Simulation<Real>& plain, Simulation<Real>& rows, const std::string& at) {
  const DemBodies x = plain.bodies(), y = rows.bodies();
  ASSERT_EQ(x.size(), y.size()) << at;
  ASSERT_EQ(std::memcmp(x.position.data(), y.position.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
  ASSERT_EQ(std::memcmp(x.velocity.data(), y.velocity.data(), x.size() * sizeof(Vec3<double>)), 0) << at;
  ASSERT_EQ(
      std::memcmp(x.angular_velocity.data(), y.angular_velocity.data(), x.size() * sizeof(Vec3<double>)), 0)
      << at;
  ASSERT_GT(plain.contact_count(), 0u) << at;
  Contacts<Real> a = plain.contacts(), b = rows.contacts();
  ASSERT_EQ(compare_contacts(b, a), "identical") << at;
  EXPECT_EQ(std::memcmp(a.previous_row.data(), b.previous_row.data(), a.size() * sizeof(std::int64_t)), 0)
      << at;
  EXPECT_EQ(std::memcmp(a.age.data(), b.age.data(), a.size() * sizeof(std::int64_t)), 0) << at;
  const DemEnergies ea = plain.energies(), eb = rows.energies();
  EXPECT_EQ(ea.kinetic, eb.kinetic) << at;
  EXPECT_EQ(ea.elastic, eb.elastic) << at;
}

// run() against the rank interface over rows whose global ids are 3i (the history's keys): halves
// of steps, every row read and written back between the halves, and twice the rows set again from
// their own state (as a relayout that moves no body).
template <class Real>
void rows_equal_run(Backend backend, bool ellipsoids) {
  const RowsScene s = rows_scene(backend, ellipsoids);
  const std::size_t n = s.bodies.size();
  std::vector<std::int64_t> ids(n);
  for (std::size_t i = 0; i < n; ++i) ids[i] = 3 * std::int64_t(i);
  Simulation<Real> plain(s.bodies, s.options);
  Simulation<Real> rows(s.bodies, s.options, ids, std::nullopt);
  std::vector<std::uint32_t> all(n);
  for (std::size_t i = 0; i < n; ++i) all[i] = static_cast<std::uint32_t>(i);
  for (int block = 0; block < 4; ++block) {
    plain.run(25);
    for (int k = 0; k < 25; ++k) {
      rows.kick_drift();
      std::vector<DemRow> state;
      rows.read_rows(all, state);
      rows.write_rows(all, state);
      rows.finish_step(std::nullopt);
    }
    const std::string at =
        std::string(ellipsoids ? "ellipsoids" : "spheres") + " step " + std::to_string(plain.steps());
    expect_same(plain, rows, at);
    if (block == 1 || block == 2) {  // set again mid-step, between the halves, as a relayout does
      plain.run(1);
      rows.kick_drift();
      const ResidentExtent e = rows.extent();
      EXPECT_GT(e.displacement, 0) << at;
      DemBodies b = s.bodies;
      const DemState st = rows.state();
      ASSERT_EQ(st.xi.size(), st.history.size()) << at;
      ASSERT_GT(st.history.size(), 0u) << at;
      for (std::size_t i = 0; i < n; ++i) b.position[i] = st.rows[i].position;
      rows.set_rows(b, ids, st);
      EXPECT_EQ(rows.extent().displacement, 0) << at;
      rows.finish_step(std::nullopt);
      expect_same(plain, rows, at + " + 1 (set again)");
    }
  }
}

template <class B>
class DemRows : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(B); }
};
TYPED_TEST_SUITE(DemRows, BackendTypes, BackendTypeNames);

TYPED_TEST(DemRows, TheRankInterfaceGivesTheTrajectoryOfRun) {
  rows_equal_run<double>(TypeParam::backend, false);
  rows_equal_run<float>(TypeParam::backend, false);
  rows_equal_run<double>(TypeParam::backend, true);
}

// A log row's terms (log_terms) of every row, summed in the tree's order, are energies() bit for
// bit, and each row's run of contacts holds exactly its contacts as A; of a few rows, their terms.
template <class Real>
void log_terms_equal_energies(Backend backend, bool ellipsoids) {
  const RowsScene s = rows_scene(backend, ellipsoids);
  const std::size_t n = s.bodies.size();
  std::vector<std::int64_t> ids(n);
  for (std::size_t i = 0; i < n; ++i) ids[i] = 2 * std::int64_t(i) + 1;
  Simulation<Real> sim(s.bodies, s.options, ids, std::nullopt);
  std::vector<std::uint32_t> all(n);
  for (std::size_t i = 0; i < n; ++i) all[i] = static_cast<std::uint32_t>(i);
  for (int block = 0; block < 3; ++block) {
    for (int k = 0; k < 30; ++k) {
      sim.kick_drift();
      sim.finish_step(std::nullopt);
    }
    const std::string at =
        std::string(ellipsoids ? "ellipsoids" : "spheres") + " step " + std::to_string(sim.steps());
    std::vector<DemLogRow> rows;
    std::vector<double> energy;
    sim.log_terms(all, rows, energy);
    ASSERT_EQ(rows.size(), n) << at;
    const Contacts<Real> c = sim.contacts();
    ASSERT_GT(c.size(), 0u) << at;
    ASSERT_EQ(energy.size(), c.size()) << at;
    std::size_t next = 0;
    for (std::size_t i = 0; i < n; ++i) {
      ASSERT_EQ(rows[i].a_begin, next) << at << " row " << i;
      ASSERT_LE(rows[i].a_end, c.size()) << at << " row " << i;
      for (std::uint32_t k = rows[i].a_begin; k < rows[i].a_end; ++k)
        ASSERT_EQ(c.id_a[k], std::int64_t(i)) << at;
      next = rows[i].a_end;
    }
    EXPECT_EQ(next, c.size()) << at;
    const DemEnergies e = sim.energies();
    const double kinetic = dem::tree_sum(n, [&](std::size_t i) { return rows[i].kinetic; });
    const double gravity = dem::tree_sum(n, [&](std::size_t i) { return rows[i].gravity; });
    const double elastic = dem::tree_sum(energy.size(), [&](std::size_t k) { return energy[k]; }) +
                           dem::tree_sum(n, [&](std::size_t i) { return rows[i].wall; });
    EXPECT_EQ(kinetic, e.kinetic) << at;
    EXPECT_EQ(gravity, e.gravity) << at;
    EXPECT_EQ(elastic, e.elastic) << at;
    EXPECT_GT(e.elastic, 0) << at;
    // a few rows, out of order: the same terms as of every row
    const std::vector<std::uint32_t> some{7, 2, static_cast<std::uint32_t>(n - 1)};
    std::vector<DemLogRow> part;
    sim.log_terms(some, part, energy);
    ASSERT_EQ(part.size(), some.size()) << at;
    for (std::size_t j = 0; j < some.size(); ++j)
      EXPECT_EQ(std::memcmp(&part[j], &rows[some[j]], sizeof(DemLogRow)), 0) << at << " row " << some[j];
  }
}

TYPED_TEST(DemRows, LogTermsSumToTheEnergies) {
  log_terms_equal_energies<double>(TypeParam::backend, false);
  log_terms_equal_energies<float>(TypeParam::backend, false);
  log_terms_equal_energies<double>(TypeParam::backend, true);
}

TYPED_TEST(DemRows, RowsOutsideTheRankAreRefused) {
  const RowsScene s = rows_scene(TypeParam::backend, false);
  Simulation<double> sim(s.bodies, s.options);
  std::vector<DemRow> out;
  EXPECT_THROW(sim.read_rows({static_cast<std::uint32_t>(s.bodies.size())}, out), UsageError);
  EXPECT_THROW(sim.write_rows({0, 1}, std::vector<DemRow>(1)), UsageError);
  std::vector<DemLogRow> terms;
  std::vector<double> energy;
  EXPECT_THROW(sim.log_terms({static_cast<std::uint32_t>(s.bodies.size())}, terms, energy), UsageError);
}

// Rows' records as the halo carries them (Simulation::set_halo): DemSphereRow (spheres), else DemRow.
std::vector<std::byte> halo_records(const std::vector<DemRow>& rows, bool spheres) {
  const std::size_t bytes = spheres ? sizeof(DemSphereRow) : sizeof(DemRow);
  std::vector<std::byte> out(rows.size() * bytes);
  for (std::size_t j = 0; j < rows.size(); ++j) {
    const DemRow& r = rows[j];
    const DemSphereRow sr{r.position, r.velocity, r.omega, r.force, r.torque};
    std::memcpy(out.data() + j * bytes, spheres ? static_cast<const void*>(&sr) : &r, bytes);
  }
  return out;
}

// The halo's rows (set_halo, gather_halo, halo_inbox, scatter_halo) carry the records read_rows and
// write_rows do, less what the receiver never reads (a sphere's momentum and orientation: 120 bytes a
// row where the rows hold no ellipsoid, unless full_records): a gather gives read_rows' bytes;
// records scattered through the inbox give the state write_rows gives (bodies and the next steps);
// rows outside the rank and a halo not set are refused.
TYPED_TEST(DemRows, TheHaloCarriesTheRowsRecords) {
  for (const bool ellipsoids : {false, true})
    for (const bool full : {false, true}) {
      const std::string at = std::string(ellipsoids ? "ellipsoids" : "spheres") + (full ? ", full" : "");
      const RowsScene s = rows_scene(TypeParam::backend, ellipsoids);
      Simulation<double> a(s.bodies, s.options), b(s.bodies, s.options);
      a.run(7);
      b.run(7);
      const std::size_t n = s.bodies.size();
      const std::vector<std::uint32_t> send = {3, 0, static_cast<std::uint32_t>(n - 1), 17, 40};
      const std::vector<std::uint32_t> receive = {5, 11, static_cast<std::uint32_t>(n - 2), 1, 90};
      std::vector<DemRow> rows;
      a.read_rows(send, rows);
      EXPECT_THROW(b.gather_halo(), Error) << "a halo not set";
      b.set_halo(send, receive, full);
      const bool spheres = !ellipsoids && !full;
      EXPECT_EQ(b.halo_record_bytes(), spheres ? 120u : 176u) << at;
      const std::vector<std::byte> expected = halo_records(rows, spheres);
      const std::byte* got = b.gather_halo();
      ASSERT_EQ(std::memcmp(got, expected.data(), expected.size()), 0) << at;
      // the other rows' records into `receive`, on both
      std::vector<DemRow> moved;
      a.read_rows({60, 61, 62, 63, 64}, moved);
      std::vector<DemRow> kept;  // a sphere's momentum and orientation stay the row's own
      a.read_rows(receive, kept);
      for (std::size_t j = 0; spheres && j < moved.size(); ++j) {
        moved[j].momentum = kept[j].momentum;
        moved[j].orientation = kept[j].orientation;
      }
      a.write_rows(receive, moved);
      const std::vector<std::byte> in = halo_records(moved, spheres);
      std::memcpy(b.halo_inbox(), in.data(), in.size());
      b.scatter_halo();
      a.run(5);
      b.run(5);
      expect_same(a, b, at);
      EXPECT_THROW(b.set_halo({static_cast<std::uint32_t>(n)}, {}), UsageError);
    }
}

// The overlapped step (finish_step_sending, halo_inbox, receive_halo) against the split step with
// the halo after it (finish_step, kick_drift, read_rows of the sent rows, write_rows of the received):
// the same records sent and the same state, contacts and energies, step after step, and a plain step
// after. The received records are the rows' own, nudged (as another rank's newer state): an interior
// contact or body computed from a received row after its scatter would differ (on the CPU the
// interior's passes run after the scatter).
template <class Real>
void overlapped_equals_split(Backend backend, bool ellipsoids, bool sends = true) {
  const RowsScene s = rows_scene(backend, ellipsoids);
  const std::size_t n = s.bodies.size();
  std::vector<std::int64_t> ids(n);
  for (std::size_t i = 0; i < n; ++i) ids[i] = 2 * std::int64_t(i);
  Simulation<Real> split(s.bodies, s.options, ids, std::nullopt);
  Simulation<Real> lap(s.bodies, s.options, ids, std::nullopt);
  // sent rows twice over (two ranks), received rows among the lattice's inner rows
  // (sends false: a rank that only receives)
  const std::vector<std::uint32_t> send =
      sends ? std::vector<std::uint32_t>{3, 40, 41, static_cast<std::uint32_t>(n - 1), 40, 100}
            : std::vector<std::uint32_t>{};
  std::vector<std::uint32_t> receive;
  for (std::uint32_t r = 70; r < 110; r += 3)
    if (r != 100) receive.push_back(r);
  split.set_halo(send, receive);
  lap.set_halo(send, receive);
  ASSERT_TRUE(lap.can_overlap());
  auto nudged = [&](Simulation<Real>& sim) {
    std::vector<DemRow> r;
    sim.read_rows(receive, r);
    for (DemRow& x : r) {
      x.position.x += 1e-3;
      x.velocity.z += 0.05;
      x.omega.y += 0.1;
    }
    return r;
  };
  split.kick_drift();
  lap.kick_drift();
  const std::vector<DemRow> first = nudged(split);
  split.write_rows(receive, first);
  lap.write_rows(receive, first);
  for (int k = 0; k < 40; ++k) {
    const std::string at = std::string(ellipsoids ? "ellipsoids" : "spheres") + " step " + std::to_string(k);
    split.finish_step(std::nullopt);
    split.kick_drift();
    std::vector<DemRow> sent;
    split.read_rows(send, sent);
    const std::vector<DemRow> in = nudged(split);
    split.write_rows(receive, in);
    const std::vector<std::byte> sent_records = halo_records(sent, !ellipsoids);
    const std::byte* out = lap.finish_step_sending(std::nullopt);
    if (!sent_records.empty()) ASSERT_EQ(std::memcmp(out, sent_records.data(), sent_records.size()), 0) << at;
    const std::vector<std::byte> in_records = halo_records(in, !ellipsoids);
    std::memcpy(lap.halo_inbox(), in_records.data(), in_records.size());
    lap.receive_halo();
    lap.kick_drift();  // nothing: the rows hold it
    const DemState a = split.state(), b = lap.state();
    ASSERT_EQ(a.rows.size(), b.rows.size()) << at;
    ASSERT_EQ(std::memcmp(a.rows.data(), b.rows.data(), a.rows.size() * sizeof(DemRow)), 0) << at;
    ASSERT_EQ(a.xi.size(), b.xi.size()) << at;
    ASSERT_EQ(std::memcmp(a.xi.data(), b.xi.data(), a.xi.size() * sizeof(Vec3<double>)), 0) << at;
    ASSERT_EQ(std::memcmp(a.wall_xi.data(), b.wall_xi.data(), a.wall_xi.size() * sizeof(Vec3<double>)), 0)
        << at;
  }
  split.finish_step(std::nullopt);
  lap.finish_step(std::nullopt);
  expect_same(split, lap, std::string(ellipsoids ? "ellipsoids" : "spheres") + " a plain step after");
}

TYPED_TEST(DemRows, TheOverlappedStepGivesTheSplitStepsBits) {
  overlapped_equals_split<double>(TypeParam::backend, false);
  overlapped_equals_split<float>(TypeParam::backend, false);
  overlapped_equals_split<double>(TypeParam::backend, true);
  overlapped_equals_split<double>(TypeParam::backend, false, false);
}

}  // namespace
}  // namespace cg::test
