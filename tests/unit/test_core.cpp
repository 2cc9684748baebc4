// Unit tests of the shared host/device math: cell coordinates, keys, the exactly-once pair rule, the
// grid plan's encoding limits, and the sphere contact formulas of docs/FORMAT.md §3.
#include <gtest/gtest.h>

#include <map>
#include <random>
#include <set>

#include "backend.hpp"
#include "core/contact.hpp"
#include "core/grid.hpp"
#include "engine.hpp"
#include "scenes.hpp"

namespace cg::test {
namespace {

// Counts, for every pair of bodies, how many cells test it under the control-bit rule; also the set
// of pairs whose cell boxes overlap. Exactly-once: every overlapping pair is tested in exactly one cell.
template <class Real>
void check_exactly_once(const Spheres& s, double cell) {
  Bounds b = compute_bounds(BodiesView{s.p, s.r, {}, {}});
  Precision prec = sizeof(Real) == 4 ? Precision::fp32 : Precision::fp64;
  Frame f = make_frame(b, cell, prec);
  GridPlan plan = plan_grid(b, f, prec);
  auto g = detail::grid_params<Real>(plan);
  std::vector<BodyCells> bc(s.r.size());
  std::map<std::uint64_t, std::vector<std::uint32_t>> cells;
  for (std::uint32_t i = 0; i < s.r.size(); ++i) {
    Sphere<Real> sp{Real(s.p[i].x - f.origin.x), Real(s.p[i].y - f.origin.y), Real(s.p[i].z - f.origin.z),
                    Real(s.r[i])};
    bc[i] = body_cells(sp, g);
    const auto lo_key = cell_key<std::uint64_t>(bc[i].lo[0], bc[i].lo[1], bc[i].lo[2], g);
    for (std::uint32_t m = 0; m < entry_count(bc[i]); ++m) {
      const std::uint64_t key = body_cell_key<std::uint64_t>(bc[i], m, g);
      cells[key].push_back(i);
      // the device's entries: from the lowest cell's key and the control byte (with the mask bits)
      ASSERT_EQ(spilled_cell_key<std::uint64_t>(lo_key, control_bits(bc[i]) | 0xC0u, m, g), key) << s.name;
    }
  }
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> tested;
  for (auto& [key, members] : cells) {
    const auto type = key_type(key, g.half_bits);
    for (std::size_t u = 0; u < members.size(); ++u)
      for (std::size_t v = u + 1; v < members.size(); ++v) {
        auto i = members[u], j = members[v];
        ASSERT_LT(i, j);
        if (test_in_cell(control_bits(bc[i]), control_bits(bc[j]), type)) ++tested[{i, j}];
      }
  }
  std::size_t overlapping = 0;
  for (std::uint32_t i = 0; i < s.r.size(); ++i)
    for (std::uint32_t j = i + 1; j < s.r.size(); ++j) {
      bool ov = true;
      for (int k = 0; k < 3; ++k) {
        const auto hi_i = bc[i].lo[k] + ((bc[i].spill >> k) & 1),
                   hi_j = bc[j].lo[k] + ((bc[j].spill >> k) & 1);
        ov = ov && bc[i].lo[k] <= hi_j && bc[j].lo[k] <= hi_i;
      }
      if (!ov) continue;
      ++overlapping;
      auto it = tested.find({i, j});
      ASSERT_NE(it, tested.end()) << s.name << ": pair " << i << "," << j << " never tested";
      EXPECT_EQ(it->second, 1) << s.name << ": pair " << i << "," << j << " tested " << it->second
                               << " times";
    }
  EXPECT_EQ(overlapping, tested.size()) << s.name << ": tests of pairs whose cells do not overlap";
}

TEST(ExactlyOnce, RandomScenes) {
  check_exactly_once<double>(random_spheres(3000, 0.5, 1.0, 1), 0);
  check_exactly_once<float>(random_spheres(3000, 0.5, 1.0, 2), 0);
  check_exactly_once<double>(random_spheres(2000, 0.01, 1.0, 3, true), 0);
  check_exactly_once<double>(random_spheres(2000, 0.5, 1.0, 4), 5.0);  // large cells
}

TEST(ExactlyOnce, AdversarialScenes) {
  check_exactly_once<double>(one_cell(200, 5), 0);
  check_exactly_once<double>(on_boundaries(6), 2.0);
  check_exactly_once<double>(on_boundaries(7), 1.0 + 1e-9);
  check_exactly_once<double>(coincident(8), 0);
  check_exactly_once<float>(tangent(9), 0);
  check_exactly_once<double>(clustered(1500, 10), 0);
}

// GPU Gems 3 skips cells with only phantom entries. Two touching spheres near a cell corner can share
// only a cell that is home to neither: skipping it would lose the contact, so we do not skip.
TEST(ExactlyOnce, PhantomOnlyCellHoldsContact) {
  GridParams<double> g{};
  g.inv_cell = 0.5;  // cell edge 2
  for (int k = 0; k < 3; ++k) {
    g.base[k] = 0;
    g.dims[k] = 8;
    g.half[k] = 4;
  }
  g.half_bits = 6;
  Sphere<double> a{4.1, 3.4, 1.0, 0.5}, b{3.4, 4.1, 1.0, 0.5};  // homes (2,1,0) and (1,2,0)
  ASSERT_TRUE(spheres_touch(a, b));                             // d = 0.99 <= 1
  BodyCells ca = body_cells(a, g), cb = body_cells(b, g);
  // the only common cell is (1,1,0): home to neither
  EXPECT_EQ(ca.lo[0], 1u);
  EXPECT_EQ(ca.lo[1], 1u);
  EXPECT_EQ(cb.lo[0], 1u);
  EXPECT_EQ(cb.lo[1], 1u);
  EXPECT_EQ(std::uint32_t(4.1 * 0.5), 2u);  // a's home x is 2
  EXPECT_EQ(std::uint32_t(4.1 * 0.5), 2u);  // b's home y is 2
  const auto key = cell_key<std::uint32_t>(1, 1, 0, g);
  EXPECT_TRUE(test_in_cell(control_bits(ca), control_bits(cb), key_type(key, g.half_bits)));
  // and the engine reports the contact
  std::vector<Vec3<double>> p{{4.1, 3.4, 1.0}, {3.4, 4.1, 1.0}, {0.5, 0.5, 0.5}, {7.5, 7.5, 7.5}};
  std::vector<double> r{0.5, 0.5, 0.5, 0.5};
  EngineOptions o;
  o.backend = Backend::cpu;
  o.cell_size = 2.0;
  Engine<double> e(o);
  auto c = e.detect(BodiesView{p, r, {}, {}});
  ASSERT_EQ(c.size(), 1u);
  EXPECT_EQ(c.id_a[0], 0);
  EXPECT_EQ(c.id_b[0], 1);
}

TEST(Grid, KeysPutTheTypeInTheTopBits) {
  GridParams<float> g{};
  g.inv_cell = 1;
  for (int k = 0; k < 3; ++k) {
    g.base[k] = 0;
    g.dims[k] = 10;
    g.half[k] = 5;
  }
  g.half_bits = 7;  // 125 super-cells
  std::set<std::uint32_t> seen;
  for (std::uint32_t x = 0; x < 10; ++x)
    for (std::uint32_t y = 0; y < 10; ++y)
      for (std::uint32_t z = 0; z < 10; ++z) {
        auto k = cell_key<std::uint32_t>(x, y, z, g);
        EXPECT_EQ(key_type(k, g.half_bits), (x & 1) | ((y & 1) << 1) | ((z & 1) << 2));
        EXPECT_LT(k, 1u << 10);
        EXPECT_TRUE(seen.insert(k).second) << "aliased key";
      }
}

TEST(Grid, CellCoordinatesAreClampedAndMonotone) {
  EXPECT_EQ(cell_coord(-1.0, 1.0, 0u, 4u), 0u);
  EXPECT_EQ(cell_coord(std::nan(""), 1.0, 0u, 4u), 0u);
  EXPECT_EQ(cell_coord(100.0, 1.0, 0u, 4u), 3u);
  EXPECT_EQ(cell_coord(2.0, 1.0, 0u, 4u), 2u);
  EXPECT_EQ(cell_coord(std::nextafter(2.0, 0.0), 1.0, 0u, 4u), 1u);
  EXPECT_EQ(cell_coord(5.5, 1.0, 4u, 4u), 1u);
}

// The tuned cell: about twice the smallest for uniform spheres at 0.4 contacts per sphere (the
// optimum measured on the GPU), at most 1.25× the smallest for a 1:1000 radius law (a cell of the
// largest diameter already holds many small bodies), the largest candidate (3×) for a nearly empty box and
// for a scene inside one cell (fewer entries, the same pairs); always a valid cell.
TEST(CellModel, TunedCellFollowsTheScene) {
  auto factor = [](const Spheres& s) {
    const Bounds b = compute_bounds(BodiesView{s.p, s.r, {}, {}});
    const double c = tuned_cell_size(b, Precision::fp64);
    EXPECT_EQ(make_frame(b, 0, Precision::fp64).cell_size, c);
    EXPECT_EQ(make_frame(b, 0, Precision::fp64, CellChoice::smallest).cell_size,
              min_cell_size(b, Precision::fp64));
    return c / min_cell_size(b, Precision::fp64);
  };
  const double uniform = factor(random_spheres(100000, 0.5, 1.0, 7));
  EXPECT_GE(uniform, 2.0);
  EXPECT_LE(uniform, 2.75);
  EXPECT_LE(factor(random_spheres(100000, 0.001, 1.0, 8, /*log_radii=*/true)), 1.25);
  EXPECT_EQ(factor(one_cell(300, 9)), 3.0);
  Spheres dilute;
  dilute.add(0, 0, 0, 1);
  dilute.add(1000, 1000, 1000, 1);
  EXPECT_EQ(factor(dilute), 3.0);
  // bounds without moments model every body at r_max: fewer entries per cell saved, still valid
  Bounds b = compute_bounds(BodiesView{dilute.p, dilute.r, {}, {}});
  b.r_sum[0] = b.r_sum[1] = b.r_sum[2] = 0;
  EXPECT_GE(tuned_cell_size(b, Precision::fp32), min_cell_size(b, Precision::fp32));
}

TEST(GridPlan, ChoosesKeyWidthAndRefusesWhatItCannotEncode) {
  Bounds b;
  b.count = 2;
  b.lo = {0, 0, 0};
  b.hi = {100, 100, 100};
  b.r_max = 0.5;
  auto f = make_frame(b, 0, Precision::fp64, CellChoice::smallest);
  EXPECT_GE(f.cell_size, 1.0);
  EXPECT_LT(f.cell_size, 1.0 + 1e-9);
  auto p = plan_grid(b, f, Precision::fp64);
  EXPECT_FALSE(p.key64);
  EXPECT_LE(p.key_bits, 32);
  EXPECT_EQ(p.base[0] % 2, 0u);

  b.hi = {1e5, 1e5, 1e5};  // 1e15 cells: 64-bit keys
  p = plan_grid(b, make_frame(b, 0, Precision::fp64), Precision::fp64);
  EXPECT_TRUE(p.key64);
  EXPECT_LE(p.key_bits, 63);

  b.hi = {1e9, 1e9, 1e9};  // 1e27 cells: refused with a message
  EXPECT_THROW(plan_grid(b, make_frame(b, 0, Precision::fp64), Precision::fp64), InputError);
  // A float broad phase (fp32, mixed) resolves 2^-23 of the extent: the cell grows with the extent so
  // no body spans three cells, and a requested cell below that is refused; an explicit frame beyond
  // 2^22 cells is refused. fp32 itself refuses this scene: its float32 world positions would be 1
  // apart at 1e7, more than a quarter of the largest radius 0.5 (check_fp32_world).
  b.hi = {1e7, 1, 1};
  EXPECT_THROW(make_frame(b, 0, Precision::fp32), InputError);
  EXPECT_GE(make_frame(b, 0, Precision::mixed).cell_size, 16 * 1.1920929e-7 * 1e7);
  EXPECT_THROW(make_frame(b, 1.0, Precision::mixed), UsageError);
  EXPECT_THROW(plan_grid(b, Frame{{0, 0, 0}, 1.0}, Precision::fp32), InputError);
  EXPECT_THROW(plan_grid(b, Frame{{0, 0, 0}, 1.0}, Precision::mixed), InputError);
  EXPECT_NO_THROW(plan_grid(b, make_frame(b, 0, Precision::fp64), Precision::fp64));
  EXPECT_THROW(make_frame(b, 0.5, Precision::fp64), UsageError);
}

TEST(Contact, SphereSphereFollowsTheContract) {
  Sphere<double> a{1, 2, 3, 1.0}, b{1, 2, 4.5, 0.75};
  auto c = sphere_sphere_contact(a, b);
  EXPECT_DOUBLE_EQ(c.distance, 1.5 - 1.75);
  EXPECT_EQ(c.normal_on_b.z, -1);  // from B to A
  EXPECT_DOUBLE_EQ(c.position_on_b.z, 4.5 - 0.75);
  EXPECT_DOUBLE_EQ(c.position_on_a.z, 3 + 1.0);
  EXPECT_DOUBLE_EQ(c.position_on_a.z, c.position_on_b.z + c.normal_on_b.z * c.distance);
  // containment: small B inside A
  Sphere<double> big{0, 0, 0, 2}, small{0.5, 0, 0, 0.25};
  auto d = sphere_sphere_contact(big, small);
  EXPECT_DOUBLE_EQ(d.distance, 0.5 - 2.25);
  EXPECT_EQ(d.normal_on_b.x, -1);
  // coincident centres
  auto e = sphere_sphere_contact(Sphere<float>{1, 1, 1, 1}, Sphere<float>{1, 1, 1, 0.5f});
  EXPECT_EQ(e.normal_on_b.x, 1);
  EXPECT_EQ(e.normal_on_b.y, 0);
  EXPECT_EQ(e.distance, -1.5f);
  EXPECT_TRUE(spheres_touch(Sphere<double>{0, 0, 0, 0.5}, Sphere<double>{1, 0, 0, 0.5}));  // touching counts
  EXPECT_FALSE(
      spheres_touch(Sphere<double>{0, 0, 0, 0.5}, Sphere<double>{std::nextafter(1.0, 2.0), 0, 0, 0.5}));
}

TEST(Contact, PlaneSpaceIsBulletsBtPlaneSpace1) {
  Vec3<double> d1, d2;
  plane_space(Vec3<double>{1, 0, 0}, d1, d2);
  EXPECT_EQ(d1.x, 0);
  EXPECT_EQ(d1.y, 1);
  EXPECT_EQ(d2.z, 1);
  plane_space(Vec3<double>{0, 0, 1}, d1, d2);  // |n.z| > √½ branch
  EXPECT_EQ(d1.y, -1);
  EXPECT_EQ(d2.x, 1);
  std::mt19937 rng(3);
  std::normal_distribution<double> g;
  for (int i = 0; i < 1000; ++i) {
    Vec3<double> n{g(rng), g(rng), g(rng)};
    n = (1 / std::sqrt(dot(n, n))) * n;
    plane_space(n, d1, d2);
    auto x = cross(n, d1);
    EXPECT_NEAR(x.x, d2.x, 1e-12);
    EXPECT_NEAR(x.y, d2.y, 1e-12);
    EXPECT_NEAR(x.z, d2.z, 1e-12);
    EXPECT_NEAR(dot(d1, d1), 1, 1e-12);
  }
}

}  // namespace
}  // namespace cg::test
