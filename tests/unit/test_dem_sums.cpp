// Granular dynamics (kernels/dem.hpp), the fixed-order sums (core/dem_sum.hpp) that make the CUDA backend's
// bodies the CPU's bit for bit: the device's per-body sort of its rows, the torques taken from the rows'
// points where they are read, and the energies' tree of chunks.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "core/dem_step.hpp"
#include "core/dem_sum.hpp"
#include "dem.hpp"

namespace cg::test {
namespace {

// sort_rows (the device's per-body sort of its rows as B): ascending, the same as std::sort, at
// every length around its switch from insertion to heapsort and far beyond, from random orders,
// reversed and already sorted.
TEST(DemSum, SortRowsSortsEveryLength) {
  std::mt19937_64 rng(31);
  for (std::size_t m = 0; m <= 70; ++m)
    for (const std::size_t big : {std::size_t(0), std::size_t(1000), std::size_t(4097)}) {
      const std::size_t len = big ? big + m : m;
      std::vector<std::uint32_t> v(len);
      for (std::size_t j = 0; j < len; ++j) v[j] = std::uint32_t(rng() % 100000);
      for (int order = 0; order < 3; ++order) {
        std::vector<std::uint32_t> w = v, want = v;
        std::sort(want.begin(), want.end());
        if (order == 1) w = want;
        if (order == 2) w.assign(want.rbegin(), want.rend());
        dem::sort_rows(w.data(), w.size());
        ASSERT_EQ(w, want) << "length " << len << " order " << order;
      }
    }
}

// Without rolling resistance a body's sums with the torques taken from the rows' points
// (contact_sums_from_points, then body_terms_after_contacts: the CUDA default) are the bits of the
// sums of the torques stored (body_terms: the CPU backend), on random rows of random bodies; with
// rolling resistance the stored torques differ (so the comparison sees the torques at all). And the
// last step's normals read as detected (fp32) give the terms of their doubles.
TEST(DemSum, TermsStoredOnlyWhereReadAreTheSameBits) {
  std::mt19937_64 rng(32);
  std::uniform_real_distribution<double> u(-1, 1);
  const std::size_t n = 300, k = 2000;
  std::vector<Vec3<double>> position(n), velocity(n), omega(n), momentum(n, {0, 0, 0}), force(n), torque(n);
  std::vector<Quat<double>> orientation(n, {1, 0, 0, 0});
  std::vector<dem::BodyProps> props(n);
  std::vector<double> radius(n);
  for (std::size_t i = 0; i < n; ++i) {
    position[i] = {10 * u(rng), 10 * u(rng), 10 * u(rng)};
    velocity[i] = {u(rng), u(rng), u(rng)};
    omega[i] = {3 * u(rng), 3 * u(rng), 3 * u(rng)};
    force[i] = {u(rng), u(rng), u(rng)};
    torque[i] = {0.1 * u(rng), 0.1 * u(rng), 0.1 * u(rng)};
    radius[i] = 0.5 + 0.1 * u(rng);
    props[i] = dem::body_props(Shape::sphere, radius[i], {0, 0, 0}, 2500);
  }
  std::vector<std::int64_t> id_a(k), id_b(k), prev(k, -1);
  std::vector<Vec3<float>> pa(k), pb(k), nb(k);
  std::vector<float> dist(k);
  for (std::size_t r = 0; r < k; ++r) id_a[r] = std::int64_t(rng() % n);
  std::sort(id_a.begin(), id_a.end());  // rows sorted by A, as the engine gives them
  for (std::size_t r = 0; r < k; ++r)
    id_b[r] = (id_a[r] + 1 + std::int64_t(rng() % (n - 1))) % std::int64_t(n);
  for (std::size_t r = 0; r < k; ++r) {
    const Vec3<double> x = position[std::size_t(id_a[r])];
    pa[r] = {float(x.x + 0.3 * u(rng)), float(x.y + 0.3 * u(rng)), float(x.z + 0.3 * u(rng))};
    pb[r] = {float(x.x + 0.3 * u(rng)), float(x.y + 0.3 * u(rng)), float(x.z + 0.3 * u(rng))};
    const Vec3<double> d{u(rng), u(rng), u(rng)};
    const Vec3<double> nd = dem::unit(d);
    nb[r] = {float(nd.x), float(nd.y), float(nd.z)};
    dist[r] = float(-0.01 * (u(rng) + 1.1));
  }
  const dem::ContactRows<float> rows{id_a.data(), id_b.data(), pa.data(),   pb.data(),
                                     nb.data(),   dist.data(), prev.data(), k};
  // the index as the CPU backend makes it: begins of A, rows by B stably
  std::vector<std::uint32_t> a_begin(n + 1, 0), b_begin(n + 1, 0), by_b(k);
  for (std::size_t r = 0; r < k; ++r) {
    ++a_begin[std::size_t(id_a[r]) + 1];
    ++b_begin[std::size_t(id_b[r]) + 1];
  }
  for (std::size_t i = 0; i < n; ++i) {
    a_begin[i + 1] += a_begin[i];
    b_begin[i + 1] += b_begin[i];
  }
  std::vector<std::uint32_t> at(b_begin.begin(), b_begin.end() - 1);
  for (std::size_t r = 0; r < k; ++r) by_b[at[std::size_t(id_b[r])]++] = std::uint32_t(r);
  const dem::BodyRowIndex index{a_begin.data(), b_begin.data(), by_b.data()};
  for (const double rolling : {0.0, 0.05}) {
    dem::StepConstants c{};
    c.law = {1e7, 4e6, 0.3, 0.5, rolling};
    c.gravity = {0, 0, -9.81};
    c.dt = 1e-5;
    c.synchronized = true;
    ASSERT_EQ(dem::torques_from_points(c), rolling == 0);
    std::vector<Vec3<double>> t_force(k), t_ta(k), t_tb(k), xi(k), normal(k);
    std::vector<double> energy(k);
    std::vector<Vec3<double>> f_stored(n), tau_stored(n), f_points(n), tau_points(n), wall_xi(1);
    std::vector<double> wall_energy(n);
    dem::BodyArrays b{
        position.data(), velocity.data(), omega.data(), momentum.data(), orientation.data(), force.data(),
        torque.data(),   props.data(),    nullptr,      nullptr,         radius.data(),      n};
    const dem::ContactTerms t{t_force.data(), t_ta.data(),   t_tb.data(), energy.data(),
                              xi.data(),      normal.data(), nullptr,     nullptr};
    for (std::size_t r = 0; r < k; ++r) dem::contact_terms(r, rows, b, c, t);
    const dem::WallTerms w{wall_xi.data(), wall_energy.data()};
    std::size_t differ = 0;
    for (std::size_t i = 0; i < n; ++i) {
      b.force = f_stored.data();
      b.torque = tau_stored.data();
      dem::body_terms(i, b, c, t, index, w);
      b.force = f_points.data();
      b.torque = tau_points.data();
      Vec3<double> f{0, 0, 0}, tau{0, 0, 0};
      dem::contact_sums_from_points(i, b, rows, t, index, f, tau);
      dem::body_terms_after_contacts(i, b, c, w, f, tau);
      ASSERT_EQ(std::memcmp(&f_stored[i], &f_points[i], sizeof(Vec3<double>)), 0) << "body " << i;
      if (std::memcmp(&tau_stored[i], &tau_points[i], sizeof(Vec3<double>)) != 0) ++differ;
    }
    if (rolling == 0)
      EXPECT_EQ(differ, 0u);
    else
      EXPECT_GT(differ, n / 2);  // the rolling torques, which the points do not give
  }
  // the last step's normals kept as detected (fp32, the CUDA default) or as doubles (ContactTerms):
  // the same terms, bit for bit, for rows with a last step (springs and normals read through it)
  std::vector<std::int64_t> with_prev(k);
  std::vector<Vec3<double>> old_xi(k), old_normal(k);
  std::vector<Vec3<float>> old_normal_f(k);
  for (std::size_t r = 0; r < k; ++r) {
    with_prev[r] = r % 3 == 0 ? -1 : std::int64_t(rng() % k);
    old_xi[r] = {1e-4 * u(rng), 1e-4 * u(rng), 1e-4 * u(rng)};
    old_normal_f[r] = nb[std::size_t(rng() % k)];  // (unit, in float)
  }
  // (apart from the loop above: GCC 12's SLP vectoriser at -O2 drops the rounding of a double to
  // float and back when both conversions meet in one loop body)
  for (std::size_t r = 0; r < k; ++r) old_normal[r] = vec_cast<double>(old_normal_f[r]);
  dem::ContactRows<float> later = rows;
  later.previous_row = with_prev.data();
  dem::StepConstants c{};
  c.law = {1e7, 4e6, 0.3, 0.5, 0.05};
  c.dt = 1e-5;
  c.synchronized = true;
  const dem::BodyArrays b{
      position.data(), velocity.data(), omega.data(), momentum.data(), orientation.data(), force.data(),
      torque.data(),   props.data(),    nullptr,      nullptr,         radius.data(),      n};
  for (std::size_t r = 0; r < k; ++r) {
    const dem::ContactResult x = dem::contact_result(r, later, b, c, old_xi.data(), old_normal.data());
    const dem::ContactResult y = dem::contact_result(r, later, b, c, old_xi.data(), old_normal_f.data());
    ASSERT_EQ(std::memcmp(&x, &y, sizeof(x)), 0) << "row " << r;
  }
}

// The energies' fixed order (core/dem_sum.hpp): chunks of kEnergyChunk summed in item order, then
// the chunks' sums the same way, level by level; the order in which a level's chunks run changes
// nothing. Values of mixed magnitudes and signs, so that another order would give other bits.
TEST(DemSum, TreeSumIsChunksThenTheirChunks) {
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(-1, 1);
  const std::size_t c = dem::kEnergyChunk;
  for (const std::size_t n : {std::size_t(0), std::size_t(1), c - 1, c, c + 1, c * c, c * c * 2 + 5}) {
    std::vector<double> v(n);
    for (std::size_t i = 0; i < n; ++i) v[i] = u(rng) * std::pow(10.0, double(int(i % 13) - 6));
    // by hand: each level's chunks, from the first item to the last
    std::vector<double> level = v;
    do {
      std::vector<double> next((level.size() + c - 1) / c, 0.0);
      for (std::size_t i = 0; i < level.size(); ++i) next[i / c] = next[i / c] + level[i];
      level.swap(next);
    } while (level.size() > 1);
    const double expected = n == 0 ? 0.0 : level[0];
    const auto value = [&](std::size_t i) { return v[i]; };
    const double serial = dem::tree_sum(n, value);
    const double backwards = dem::tree_sum(n, value, [](std::size_t chunks, auto&& f) {
      for (std::size_t k = chunks; k-- > 0;) f(k);
    });
    EXPECT_EQ(std::memcmp(&serial, &expected, sizeof(double)), 0) << n << " items";
    EXPECT_EQ(std::memcmp(&backwards, &expected, sizeof(double)), 0) << n << " items";
    if (n > c * c) {  // the plain sum in item order differs: the test can tell the orders apart
      double plain = 0;
      for (double x : v) plain = plain + x;
      EXPECT_NE(plain, expected) << n << " items";
    }
  }
}

}  // namespace
}  // namespace cg::test
