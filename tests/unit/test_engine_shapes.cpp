// Bodies with shapes through Engine<Real>::detect (issue #11 item 6, issue #12's engine part): seeded
// ellipsoid and mixed scenes on the CPU backend against a brute-force all-pairs reference built from
// the exact long-double solver (src/reference/ellipsoid_reference.hpp, which shares no code with the
// engine); sphere-only scenes unchanged by shape rows; bad shape rows → InputError naming the body;
// CPU vs CUDA bit-identical on shape scenes, host arrays and device arrays (CUDA cases skip, visibly,
// without a GPU).
//
// Tolerances. The reference solves the world-frame double data; the engine solves Real-rounded local
// data (centre − origin, semi-axes, the rotation built in double then rounded), so besides the core's
// solver tolerances (test_ellipsoid_contact.cpp: distance 1e-6·s fp32, 1e-12·s fp64; positions
// 4e-4·κ·s, 2e-10·κ·s; normals 5e-4·κ, 1e-9·κ rad; s = sum of the largest semi-axes, κ = the larger axis
// ratio) every quantity carries the input rounding, 64·eps·(L + s) with L the scene's extent:
//   band (borderline)  = dist·s + 64·eps·(L + s): outside it every decision must match the reference;
//   distance error     <= band;  positions <= pos·κ·s + 64·eps·κ·(L + s);  normal angle <= angle·κ +
//   64·eps·κ·(L + s)/s.  Pairs with two equally deep exits (reference second_gap <= 4·band) compare
//   the distance only.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <map>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "backend.hpp"
#include "core/shape_narrow.hpp"
#include "engine.hpp"
#include "reference/ellipsoid_reference.hpp"
#include "scenes.hpp"
#include "support/contacts_equal.hpp"

#if defined(CONTACTGRID_HAVE_CUDA)
#include <cuda_runtime.h>
#endif

namespace cg::test {
namespace {

exact::Body reference_body(const ShapeScene& s, std::size_t i) {
  const exact::V c{s.p[i].x, s.p[i].y, s.p[i].z};
  if (s.shape[i] == Shape::sphere) return exact::make_body(c, {s.r[i], s.r[i], s.r[i]}, {1, 0, 0, 0});
  return exact::make_body(c, {s.axes[i].x, s.axes[i].y, s.axes[i].z},
                          {s.q[i].w, s.q[i].x, s.q[i].y, s.q[i].z});
}

double aspect(const ShapeScene& s, std::size_t i) {
  if (s.shape[i] == Shape::sphere) return 1;
  const Vec3<double> e = s.axes[i];
  return std::max(e.x, std::max(e.y, e.z)) / std::min(e.x, std::min(e.y, e.z));
}

template <class Real>
struct Tol {
  static constexpr bool fp32 = std::is_same_v<Real, float>;
  static constexpr double dist = fp32 ? 1e-6 : 1e-12, pos = fp32 ? 4e-4 : 2e-10, angle = fp32 ? 5e-4 : 1e-9;
  static double input(double L, double s) {
    return 64 * double(std::numeric_limits<Real>::epsilon()) * (L + s);
  }
};

struct Counts {
  int close = 0, contacts = 0, borderline = 0, ambiguous = 0;
};

// Every pair of the scene against the reference (see the file comment); `c` from Fields::full.
template <class Real>
Counts compare_with_reference(const ShapeScene& s, const Contacts<Real>& c) {
  std::map<std::pair<std::int64_t, std::int64_t>, std::size_t> rows;
  for (std::size_t k = 0; k < c.size(); ++k) {
    EXPECT_LT(c.id_a[k], c.id_b[k]);
    if (k > 0) {
      EXPECT_TRUE(std::make_pair(c.id_a[k - 1], c.id_b[k - 1]) < std::make_pair(c.id_a[k], c.id_b[k]));
    }
    rows[{c.id_a[k], c.id_b[k]}] = k;
  }
  Counts n;
  const std::size_t nb = s.p.size();
  for (std::size_t i = 0; i < nb; ++i)
    for (std::size_t j = i + 1; j < nb; ++j) {
      const double dx = s.p[i].x - s.p[j].x, dy = s.p[i].y - s.p[j].y, dz = s.p[i].z - s.p[j].z;
      const double sc = s.r[i] + s.r[j];
      const auto it = rows.find({std::int64_t(i), std::int64_t(j)});
      if (std::sqrt(dx * dx + dy * dy + dz * dz) > sc * (1 + 1e-3)) {  // bounding spheres apart
        EXPECT_TRUE(it == rows.end())
            << s.name << ": pair " << i << "," << j << " beyond its bounding spheres";
        continue;
      }
      ++n.close;
      exact::Pair p{reference_body(s, i), reference_body(s, j), {}};
      p.r = exact::sub(p.a.centre, p.b.centre);
      const bool spheres = s.shape[i] == Shape::sphere && s.shape[j] == Shape::sphere;
      exact::Reference ref{};
      if (spheres) {
        const exact::LD d = exact::norm(p.r);
        ref.distance = d - exact::LD(sc);
        ref.n = exact::unit(p.r);
        ref.position_on_b = exact::add(p.b.centre, exact::scale(s.r[j], ref.n));
        ref.position_on_a = exact::sub(p.a.centre, exact::scale(s.r[i], ref.n));
        ref.second_gap = std::numeric_limits<exact::LD>::infinity();
      } else {
        ref = exact::exact_contact(p, 4000);
      }
      const double kappa = std::max(aspect(s, i), aspect(s, j));
      const double in = Tol<Real>::input(s.extent, sc);
      const double band = Tol<Real>::dist * sc + in;
      const std::string what = s.name + ": pair " + std::to_string(i) + "," + std::to_string(j) +
                               " reference distance " + std::to_string(double(ref.distance));
      if (std::abs(double(ref.distance)) <= band) {
        ++n.borderline;  // either decision is correct
      } else if (ref.distance < 0) {
        EXPECT_TRUE(it != rows.end()) << what << ": contact missing";
      } else {
        EXPECT_TRUE(it == rows.end()) << what << ": extra contact";
      }
      if (it == rows.end()) continue;
      ++n.contacts;
      const std::size_t k = it->second;
      EXPECT_NEAR(double(c.distance[k]), double(ref.distance), band) << what;
      const Vec3<double> nrm{double(c.normal_on_b[k].x), double(c.normal_on_b[k].y),
                             double(c.normal_on_b[k].z)};
      const exact::V rn = ref.n;
      const Vec3<double> rnd{double(rn.x), double(rn.y), double(rn.z)}, cr = cross(nrm, rnd);
      const double angle = std::atan2(std::sqrt(dot(cr, cr)), dot(nrm, rnd));  // exact near 0, unlike acos
      if (double(ref.second_gap) <= 4 * band && angle > Tol<Real>::angle * kappa + kappa * in / sc) {
        ++n.ambiguous;
        continue;
      }
      EXPECT_LE(angle, Tol<Real>::angle * kappa + kappa * in / sc) << what << ": normal";
      auto err = [](Vec3<Real> a, exact::V b) {
        const double x = double(a.x) - double(b.x), y = double(a.y) - double(b.y),
                     z = double(a.z) - double(b.z);
        return std::sqrt(x * x + y * y + z * z);
      };
      const double pos_tol = Tol<Real>::pos * kappa * sc + kappa * in;
      EXPECT_LE(err(c.position_on_a[k], ref.position_on_a), pos_tol) << what << ": position_on_a";
      EXPECT_LE(err(c.position_on_b[k], ref.position_on_b), pos_tol) << what << ": position_on_b";
      // local points in the body frame: centre + R · local gives the world point back
      EXPECT_TRUE(c.full);
      for (int side = 0; side < 2; ++side) {
        const std::size_t b = side == 0 ? i : j;
        const Vec3<Real> local = side == 0 ? c.local_point_a[k] : c.local_point_b[k];
        const Vec3<Real> world = side == 0 ? c.position_on_a[k] : c.position_on_b[k];
        exact::V l{local.x, local.y, local.z};
        if (s.shape[b] == Shape::ellipsoid)
          l = exact::rotate_hamilton({s.q[b].w, s.q[b].x, s.q[b].y, s.q[b].z}, l);
        const exact::V back = exact::add({s.p[b].x, s.p[b].y, s.p[b].z}, l);
        EXPECT_LE(err(world, back), 4 * in) << what << ": local point " << side;
      }
    }
  return n;
}

template <class Real>
class EngineShapesTest : public ::testing::Test {};
using Reals = ::testing::Types<double, float>;
struct RealNames {
  template <class T>
  static std::string GetName(int) {
    return sizeof(T) == 4 ? "fp32" : "fp64";
  }
};
TYPED_TEST_SUITE(EngineShapesTest, Reals, RealNames);

std::vector<ShapeScene> reference_scenes() {
  return {make_scene("ellipsoids", 11, 150, 1.0, 8.0), make_scene("mixed", 12, 150, 0.5, 8.0),
          make_scene("mixed", 13, 150, 0.3, 8.0), make_scene("dense ellipsoids", 14, 120, 1.0, 5.5)};
}

TYPED_TEST(EngineShapesTest, CpuMatchesBruteForceReference) {
  using Real = TypeParam;
  for (const ShapeScene& s : reference_scenes()) {
    Engine<Real> e({.backend = Backend::cpu, .fields = Fields::full, .threads = 2});
    const Contacts<Real> c = e.detect(s.view());
    const Counts n = compare_with_reference(s, c);
    EXPECT_EQ(e.stats().narrow_unconverged, 0u) << s.name;
    EXPECT_EQ(e.stats().contacts, c.size());
    EXPECT_GE(e.stats().candidates, c.size());
    EXPECT_GT(n.contacts, 10) << s.name << ": the scene should have contacts";
    std::printf(
        "[shapes] %-24s %s: %zu bodies (%llu ellipsoids), %d close pairs, %d contacts, %d borderline, "
        "%d ambiguous, %llu fallbacks\n",
        s.name.c_str(), sizeof(Real) == 4 ? "fp32" : "fp64", s.p.size(),
        static_cast<unsigned long long>(e.stats().ellipsoids), n.close, n.contacts, n.borderline, n.ambiguous,
        static_cast<unsigned long long>(e.stats().narrow_fallbacks));
  }
}

template <class Real>
void expect_identical(const Contacts<Real>& x, const Contacts<Real>& y, const std::string& what) {
  ASSERT_EQ(x.size(), y.size()) << what;
  ASSERT_EQ(x.full, y.full) << what;
  EXPECT_EQ(test::compare_contacts(x, y), "identical") << what;
}

// Shape rows that hold only spheres select the sphere path: the same bits as no shape rows, every
// candidate a contact (no narrow rejection), rows equal to the closed form.
TYPED_TEST(EngineShapesTest, SphereOnlyScenesUnchanged) {
  using Real = TypeParam;
  ShapeScene s = make_scene("spheres", 21, 400, 0.0, 10.0);
  for (Fields f : {Fields::basic, Fields::full}) {
    Engine<Real> e({.backend = Backend::cpu, .fields = f, .threads = 2});
    BodiesView plain{s.p, s.r, {}, {}};
    const Contacts<Real> a = e.detect(plain);
    const EngineStats plain_stats = e.stats();
    const Contacts<Real> b = e.detect(s.view());
    expect_identical(a, b, std::string("spheres with and without shape rows ") + to_string(f));
    EXPECT_EQ(e.stats().candidates, b.size());
    EXPECT_EQ(plain_stats.candidates, a.size());
    EXPECT_EQ(e.stats().ellipsoids, 0u);
    ASSERT_GT(a.size(), 0u);
    for (std::size_t k = 0; k < a.size(); ++k) {  // the closed form in double (docs/FORMAT.md §3)
      const std::size_t i = std::size_t(a.id_a[k]), j = std::size_t(a.id_b[k]);
      const double dx = s.p[i].x - s.p[j].x, dy = s.p[i].y - s.p[j].y, dz = s.p[i].z - s.p[j].z;
      const double d = std::sqrt(dx * dx + dy * dy + dz * dz) - (s.r[i] + s.r[j]);
      EXPECT_NEAR(double(a.distance[k]), d, 64 * double(std::numeric_limits<Real>::epsilon()) * 20);
    }
  }
}

// The same rows for any thread count, and a starved solver is flagged (never silently wrong).
TYPED_TEST(EngineShapesTest, ThreadInvariantAndStarvedSolverCounted) {
  using Real = TypeParam;
  const ShapeScene s = make_scene("mixed", 31, 300, 0.6, 9.0);
  Engine<Real> one({.backend = Backend::cpu, .fields = Fields::full, .threads = 1});
  Engine<Real> two({.backend = Backend::cpu, .fields = Fields::full, .threads = 2});
  expect_identical(one.detect(s.view()), two.detect(s.view()), "threads 1 vs 2");
  EXPECT_EQ(one.stats().narrow_evaluations, two.stats().narrow_evaluations);
  EXPECT_EQ(one.stats().narrow_max_evaluations, two.stats().narrow_max_evaluations);
  Engine<Real> starved({.backend = Backend::cpu, .ellipsoid_max_iterations = 1});
  starved.detect(s.view());
  EXPECT_GT(starved.stats().narrow_fallbacks + starved.stats().narrow_unconverged, 0u);
  EXPECT_THROW(Engine<Real>({.backend = Backend::cpu, .ellipsoid_tolerance = -1}), UsageError);
  EXPECT_THROW(Engine<Real>({.backend = Backend::cpu, .ellipsoid_max_iterations = -2}), UsageError);
}

// One CPU detection of scene s with the candidate filter `filter` requested (the host backend's test
// hook; spheres_touch: the scene's default), its stats in `stats`.
template <class Real>
Contacts<Real> host_detect(const ShapeScene& s, CandidateFilter filter, EngineStats& stats) {
  constexpr Precision prec = sizeof(Real) == 4 ? Precision::fp32 : Precision::fp64;
  const BodiesView v = s.view();
  const Bounds b = compute_bounds(v);
  detail::DetectJob<Real> job{v, plan_grid(b, make_frame(b, 0, prec), prec), {}, Fields::full};
  job.grid = detail::grid_params<Real>(job.plan);
  job.ellipsoids = validate_shapes(v);
  EXPECT_GT(job.ellipsoids, 0u);
  detail::HostBackend backend{2, filter};
  Contacts<Real> out;
  StageTimes times;
  detail::run_stages(backend, job, out, times, stats);
  return out;
}

// The looser cell-rule filter (CUDA: forced by Tuning::candidates) proposes more candidates; the
// shape narrow stage rejects them to the same rows as the bounding-sphere filter.
TYPED_TEST(EngineShapesTest, CellFilterGivesTheSameRows) {
  using Real = TypeParam;
  const ShapeScene s = make_scene("mixed", 35, 400, 0.5, 10.0);
  EngineStats sx, sy;
  const Contacts<Real> x = host_detect<Real>(s, CandidateFilter::spheres_touch, sx);
  const Contacts<Real> y = host_detect<Real>(s, CandidateFilter::cells, sy);
  expect_identical(x, y, "bounding spheres vs cells");
  EXPECT_GT(sy.candidates, sx.candidates);
  EXPECT_GT(sx.candidates, x.size()) << "some bounding spheres touch where the shapes do not";
}

// The centre cut (core/centre_cut.hpp, the default for scenes with ellipsoids) and the cells of the
// shapes' boxes it brings remove only candidates the narrow stage rejects: the same rows, bit for bit,
// and the same solver work as every bounding-sphere pair, on scenes with general, equal-axis and sphere
// bodies, deep overlaps, pairs with nearly coincident centres (fp32: solved in fp64), a scene far from
// the origin and one with 1:30 needles; and it removes many candidates and pair tests.
TYPED_TEST(EngineShapesTest, CentreCutGivesTheSameRows) {
  using Real = TypeParam;
  constexpr Precision prec = sizeof(Real) == 4 ? Precision::fp32 : Precision::fp64;
  std::vector<ShapeScene> scenes = {make_scene("ellipsoids", 71, 600, 1.0, 9.0),
                                    make_scene("mixed", 72, 700, 0.9, 10.0),  // cut: >= 4 in 5
                                    make_scene("dense ellipsoids", 73, 900, 1.0, 7.0)};
  ShapeScene partners = make_scene("ellipsoids", 74, 300, 1.0, 8.0);
  for (std::size_t i = 0, n = partners.p.size(); i < 40; ++i) {  // near-coincident centres, equal axes
    const double delta = std::pow(10.0, -3 - int(i % 8));
    partners.p.push_back({partners.p[i].x + delta, partners.p[i].y, partners.p[i].z - delta});
    const std::size_t j = (i * 5 + 1) % n;
    partners.r.push_back(partners.r[j]), partners.shape.push_back(partners.shape[j]);
    partners.axes.push_back(i % 3 ? partners.axes[j] : Vec3<double>{0.6, 0.6, 0.6});
    partners.q.push_back(partners.q[j]);
    if (i % 3 == 0) partners.r.back() = 0.6;
  }
  scenes.push_back(partners);
  ShapeScene far = make_scene("ellipsoids", 75, 500, 1.0, 9.0);
  for (Vec3<double>& p : far.p) p = {p.x + 3e5, p.y - 2e5, p.z + 1e5};
  scenes.push_back(far);
  ShapeScene needles = make_scene("needles", 76, 600, 1.0, 8.0);  // every third 1:30 (PW's band is wide)
  for (std::size_t i = 0; i < needles.p.size(); i += 3) {
    needles.axes[i] = {1.2, 0.04, 0.06};
    needles.r[i] = 1.2;
  }
  scenes.push_back(needles);
  std::uint64_t cut_candidates = 0, all_candidates = 0, cut_tests = 0, all_tests = 0;
  for (const ShapeScene& s : scenes) {
    SCOPED_TRACE(s.name);
    EngineStats sx, sy;
    const Contacts<Real> x = host_detect<Real>(s, CandidateFilter::spheres_touch, sx);
    const Contacts<Real> y = host_detect<Real>(s, CandidateFilter::bounding_spheres, sy);
    expect_identical(x, y, s.name + ": centre cut vs bounding spheres");
    EXPECT_LT(sx.pair_tests, sy.pair_tests) << "the cells of the shapes' boxes: fewer pairs to test";
    EXPECT_LE(sx.candidates, sy.candidates);
    EXPECT_GE(sx.candidates, x.size());
    EXPECT_EQ(sx.narrow_fallbacks, sy.narrow_fallbacks);
    EXPECT_EQ(sx.narrow_unconverged, sy.narrow_unconverged);
    EXPECT_EQ(sx.narrow_solver_runs, sy.narrow_solver_runs);
    EXPECT_EQ(sx.narrow_evaluations, sy.narrow_evaluations);
    EXPECT_EQ(sx.fp64_rows, sy.fp64_rows);
    cut_candidates += sx.candidates;
    all_candidates += sy.candidates;
    cut_tests += sx.pair_tests;
    all_tests += sy.pair_tests;
  }
  std::printf("[centre cut] %s: %llu of %llu bounding-sphere candidates kept, %llu of %llu pair tests\n",
              to_string(prec), static_cast<unsigned long long>(cut_candidates),
              static_cast<unsigned long long>(all_candidates), static_cast<unsigned long long>(cut_tests),
              static_cast<unsigned long long>(all_tests));
  EXPECT_LT(cut_candidates, all_candidates * 4 / 5) << "the cut should remove many candidates";
}

// Both backends run the narrow stage of shapes as the device does: triage (first start + the cheap
// certificates), settle (the first start again with every certificate) for the candidates triage left,
// the whole solve for the ones still hard, and the row rebuilt from the kept minimiser
// (row_from). That must give the decisions, flags and bits of one whole solve per candidate (accept(),
// row()), and the scene must exercise both passes. fp32: the pairs with nearly coincident centres
// (appended: partners 1e-5 … 1e-11 apart) are solved in fp64 on every path, counted alike.
TYPED_TEST(EngineShapesTest, ThreePassNarrowEqualsOneWholeSolve) {
  using Real = TypeParam;
  using Verdict = typename ShapeDecide<Real>::Verdict;
  ShapeScene s = make_scene("mixed", 37, 200, 0.6, 7.0);
  for (std::size_t i = 0, n = s.p.size(); i < n && i < 28; ++i) {  // a partner for 28 bodies
    const double delta = std::pow(10.0, -5 - int(i % 7));
    s.p.push_back({s.p[i].x + delta, s.p[i].y - 0.6 * delta, s.p[i].z + 0.8 * delta});
    const std::size_t j = (i * 7 + 3) % n;  // another body's shape (either kind)
    s.r.push_back(s.r[j]), s.shape.push_back(s.shape[j]), s.axes.push_back(s.axes[j]), s.q.push_back(s.q[j]);
  }
  std::vector<Sphere<Real>> sph;
  std::vector<PackedShape<Real>> packed;
  for (std::size_t i = 0; i < s.p.size(); ++i) {
    sph.push_back({Real(s.p[i].x - 1), Real(s.p[i].y - 2), Real(s.p[i].z - 3), Real(s.r[i])});
    const double semi[3] = {s.axes[i].x, s.axes[i].y, s.axes[i].z},
                 q[4] = {s.q[i].w, s.q[i].x, s.q[i].y, s.q[i].z};
    packed.push_back(pack_shape<Real>(static_cast<std::uint8_t>(s.shape[i]), semi, q));
  }
  const NarrowBodies<Real> world{
      sph.data(), reinterpret_cast<const double*>(s.p.data()), s.r.data(), {1, 2, 3}};
  const ShapeRowsView rows{reinterpret_cast<const double*>(s.axes.data()),
                           reinterpret_cast<const double*>(s.q.data())};
  const ShapeDecide<Real> d{world, packed.data(), {}, rows};
  int contacts = 0, unsettled = 0, hard = 0, certified = 0, fp64 = 0, fp64_hard = 0, resumed = 0;
  NarrowFlags work;  // the solver's work over both passes, as the engine counts it
  for (std::uint32_t a = 0; a < sph.size(); ++a)
    for (std::uint32_t b = a + 1; b < sph.size(); ++b) {
      if (!spheres_touch(sph[a], sph[b])) continue;
      NarrowFlags f1, f2;
      const bool x = d.accept(a, b, f1);
      Vec3<Real> n{};
      Verdict v = d.triage(a, b, f2, n);
      const bool in_triage = v != Verdict::hard;
      if (!in_triage) {
        ++unsettled;
        v = d.settle(a, b, f2, n);
        // settle going on from the first start that triage kept: the same verdict, normal and work
        FirstStart<Real> first;
        NarrowFlags f3;
        Vec3<Real> n3{};
        ASSERT_EQ(d.triage(a, b, f3, n3, &first), Verdict::hard);
        NarrowFlags f4;
        EXPECT_EQ(d.settle(a, b, f4, n3, &first), v) << a << "," << b;
        NarrowFlags f5;
        Vec3<Real> n5{};
        d.settle(a, b, f5, n5);
        EXPECT_EQ(std::memcmp(&n3, &n5, sizeof(n3)), 0) << a << "," << b;
        EXPECT_EQ(f4.evaluations, f5.evaluations) << a << "," << b;
        EXPECT_EQ(f4.solver_runs, f5.solver_runs) << a << "," << b;
        EXPECT_EQ(f4.unconverged, f5.unconverged) << a << "," << b;
        ++resumed;
      }
      if (v == Verdict::hard) {
        ++hard;
        fp64_hard += d.in_fp64(a, b) ? 1 : 0;
        v = d.solve(a, b, f2, n) ? Verdict::accept : Verdict::reject;
      } else if (in_triage && d.general_pair(a, b) && x) {
        ++certified;
      }
      ASSERT_EQ(x, v == Verdict::accept) << a << "," << b;
      work.add(f2);
      EXPECT_EQ(f1.fallbacks, f2.fallbacks);
      EXPECT_EQ(f1.unconverged, f2.unconverged);
      EXPECT_EQ(f1.fp64_rows, f2.fp64_rows);
      fp64 += d.both_spheres(a, b) ? 0 : int(f1.fp64_rows);
      if (!x) continue;
      ++contacts;
      const ContactRow<Real> kept = d.row_from(a, b, n, true), again = d.row(a, b, true);
      bool same = true;  // every field, bitwise (not the struct: padding)
      zip_contact_fields(kept, again, true, [&](auto, const auto& u, const auto& w) {
        same = same && std::memcmp(&u, &w, sizeof(u)) == 0;
      });
      EXPECT_TRUE(same) << a << "," << b;
    }
  EXPECT_GT(contacts, 20);
  EXPECT_GT(unsettled, fp64_hard) << "no candidate took the settle pass";
  EXPECT_EQ(resumed, unsettled);
  EXPECT_GT(hard, 0) << "no candidate took the whole solve";
  EXPECT_GT(certified, 0) << "no ellipsoid contact was certified by the first start";
  if (std::is_same_v<Real, float>)
    EXPECT_GE(fp64, 20) << "the nearly coincident pairs with an ellipsoid were not solved in fp64";
  else
    EXPECT_EQ(fp64, 0);
  // The engine's work counters are these sums (fp64 solves from the world doubles, so in any frame).
  // (a pair solved in fp64 runs once, in the second pass)
  // (triage's certified contacts; triage + settle for each unsettled general pair; the whole solves)
  EXPECT_GE(work.solver_runs, std::uint32_t(certified + 2 * (unsettled - fp64_hard) + (hard - fp64_hard)));
  EXPECT_GT(work.evaluations, 2 * work.solver_runs);
  EXPECT_LE(work.max_evaluations, work.evaluations);
  if constexpr (std::is_same_v<Real, double>) {
    Engine<Real> e({.backend = Backend::cpu});
    e.detect(s.view());
    EXPECT_EQ(e.stats().narrow_hard, std::uint64_t(hard));
    EXPECT_EQ(e.stats().narrow_unsettled, std::uint64_t(unsettled));
    EXPECT_EQ(e.stats().narrow_solver_runs, work.solver_runs);
    EXPECT_EQ(e.stats().narrow_evaluations, work.evaluations);
    EXPECT_EQ(e.stats().narrow_max_evaluations, work.max_evaluations);
  }
}

// Bad rows → InputError whose text names the body's id.
void expect_bad(const ShapeScene& s, const std::vector<std::int64_t>& ids, const std::string& id_text,
                const std::string& what) {
  BodiesView v = s.view();
  v.id = ids;
  Engine<double> e({.backend = Backend::cpu});
  try {
    e.detect(v);
    ADD_FAILURE() << what << ": no InputError";
  } catch (const InputError& err) {
    EXPECT_NE(std::string(err.what()).find("body " + id_text + ":"), std::string::npos)
        << what << ": " << err.what();
  }
}

TEST(EngineShapes, BadShapeInputNamesTheBody) {
  const ShapeScene base = make_scene("bad", 41, 20, 1.0, 6.0);
  std::vector<std::int64_t> ids;
  for (int i = 0; i < 20; ++i) ids.push_back(100 + 3 * i);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  auto with = [&](auto edit) {
    ShapeScene s = base;
    edit(s);
    return s;
  };
  expect_bad(with([](ShapeScene& s) { s.axes[5].y = 0; }), ids, "115", "zero semi-axis");
  expect_bad(with([](ShapeScene& s) { s.axes[5].z = -0.5; }), ids, "115", "negative semi-axis");
  expect_bad(with([&](ShapeScene& s) { s.axes[7].x = nan; }), ids, "121", "NaN semi-axis");
  expect_bad(with([](ShapeScene& s) { s.q[3] = {0, 0, 0, 0}; }), ids, "109", "zero quaternion");
  expect_bad(with([](ShapeScene& s) { s.q[3] = {1.1, 0, 0, 0}; }), ids, "109", "quaternion norm 1.1");
  expect_bad(with([&](ShapeScene& s) { s.q[4].x = nan; }), ids, "112", "NaN quaternion");
  expect_bad(with([&](ShapeScene& s) { s.p[9].z = nan; }), ids, "127", "NaN position");
  expect_bad(with([](ShapeScene& s) { s.r[2] *= 1.5; }), ids, "106", "bounding radius not the max axis");
  expect_bad(with([](ShapeScene& s) { s.shape[8] = static_cast<Shape>(7); }), ids, "124", "unknown kind");
  // the first bad body is named; a near-unit quaternion (float32 rounding) passes
  expect_bad(with([](ShapeScene& s) { s.axes[12].x = 0, s.axes[4].y = -1; }), ids, "112", "first bad body");
  ShapeScene ok = with([](ShapeScene& s) { s.q[0].w *= 1 + 1e-7; });
  EXPECT_NO_THROW(Engine<double>({.backend = Backend::cpu}).detect(ok.view()));
  // row counts must match
  ShapeScene short_rows = base;
  short_rows.q.pop_back();
  EXPECT_THROW(Engine<double>({.backend = Backend::cpu}).detect(short_rows.view()), InputError);
  // resident shape rows must match the bodies in length (their contents are checked by detect_resident)
  Engine<double> r({.backend = Backend::cpu});
  EXPECT_THROW(r.set_resident(short_rows.view()), UsageError);
}

// ---- CUDA: bit-identical to the CPU backend on shape scenes (skips without a GPU) ----

#define CG_SKIP_WITHOUT_CUDA()                                                                        \
  do {                                                                                                \
    if (!::cg::cuda_available()) GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped"; \
  } while (0)

std::vector<ShapeScene> bit_scenes() {
  return {make_scene("ellipsoids", 51, 600, 1.0, 12.0), make_scene("mixed", 52, 800, 0.4, 13.0),
          make_scene("sparse ellipsoids", 53, 300, 0.05, 14.0),
          make_scene("dense ellipsoids", 54, 1500, 1.0, 8.0)};  // deep overlaps: hard pairs
}

// Both ways of running the hard pairs' whole start set on the device (cuda/narrow.cuh: one warp per pair,
// the default for short lists, and one thread per pair, CONTACTGRID_CUDA_WARP_SOLVE=0) give the CPU's bits.
TYPED_TEST(EngineShapesTest, CudaBitIdenticalToCpu) {
  CG_SKIP_WITHOUT_CUDA();
  using Real = TypeParam;
  std::uint64_t hard = 0;
  for (const char* warp_solve : {"1", "0"}) {
    ::setenv("CONTACTGRID_CUDA_WARP_SOLVE", warp_solve, 1);
    for (const ShapeScene& s : bit_scenes())
      for (Fields f : {Fields::basic, Fields::full}) {
        Engine<Real> cpu({.backend = Backend::cpu, .fields = f});
        Engine<Real> gpu({.backend = Backend::cuda, .fields = f});
        const Contacts<Real> a = cpu.detect(s.view());
        const Contacts<Real> b = gpu.detect(s.view());
        hard += gpu.stats().narrow_hard;
        expect_identical(a, b, s.name + " " + to_string(f) + " warp_solve " + warp_solve);
        EXPECT_EQ(cpu.stats().candidates, gpu.stats().candidates) << s.name;
        EXPECT_EQ(cpu.stats().narrow_fallbacks, gpu.stats().narrow_fallbacks) << s.name;
        EXPECT_EQ(cpu.stats().narrow_unconverged, gpu.stats().narrow_unconverged) << s.name;
        EXPECT_EQ(gpu.stats().ellipsoids, cpu.stats().ellipsoids) << s.name;
        EXPECT_EQ(cpu.stats().narrow_hard, gpu.stats().narrow_hard) << s.name;
        EXPECT_EQ(cpu.stats().narrow_solver_runs, gpu.stats().narrow_solver_runs) << s.name;
        EXPECT_EQ(cpu.stats().narrow_evaluations, gpu.stats().narrow_evaluations) << s.name;
        EXPECT_EQ(cpu.stats().narrow_max_evaluations, gpu.stats().narrow_max_evaluations) << s.name;
      }
  }
  ::unsetenv("CONTACTGRID_CUDA_WARP_SOLVE");
  EXPECT_GT(hard, 0u) << "the scenes should have pairs that take the whole start set";
  // without the centre cut (CONTACTGRID_CUDA_CANDIDATES=bounding): more candidates, the same rows
  ::setenv("CONTACTGRID_CUDA_CANDIDATES", "bounding", 1);
  for (const ShapeScene& s : bit_scenes()) {
    Engine<Real> cpu({.backend = Backend::cpu, .fields = Fields::full});
    Engine<Real> gpu({.backend = Backend::cuda, .fields = Fields::full});
    const Contacts<Real> a = cpu.detect(s.view());
    const Contacts<Real> b = gpu.detect(s.view());
    expect_identical(a, b, s.name + " bounding spheres on the device");
    EXPECT_LE(cpu.stats().candidates, gpu.stats().candidates) << s.name;
    EXPECT_EQ(cpu.stats().narrow_solver_runs, gpu.stats().narrow_solver_runs) << s.name;
    EXPECT_EQ(cpu.stats().narrow_evaluations, gpu.stats().narrow_evaluations) << s.name;
  }
  ::unsetenv("CONTACTGRID_CUDA_CANDIDATES");
}

#if defined(CONTACTGRID_HAVE_CUDA)
// The scene's arrays in DEVICE memory (freed on destruction).
struct DeviceScene {
  std::vector<void*> blocks;
  DeviceBodiesView v;
  template <class T>
  const T* up(const std::vector<T>& h) {
    void* d = nullptr;
    EXPECT_EQ(cudaMalloc(&d, h.size() * sizeof(T) + 1), cudaSuccess);
    EXPECT_EQ(cudaMemcpy(d, h.data(), h.size() * sizeof(T), cudaMemcpyHostToDevice), cudaSuccess);
    blocks.push_back(d);
    return static_cast<const T*>(d);
  }
  explicit DeviceScene(const ShapeScene& s) {
    v.position = reinterpret_cast<const double*>(up(s.p));
    v.radius = up(s.r);
    v.shape = up(s.shape);
    v.semi_axes = reinterpret_cast<const double*>(up(s.axes));
    v.orientation = reinterpret_cast<const double*>(up(s.q));
    v.count = s.p.size();
  }
  ~DeviceScene() {
    for (void* d : blocks) cudaFree(d);
  }
};
#endif

TYPED_TEST(EngineShapesTest, CudaDeviceArraysWithShapes) {
  CG_SKIP_WITHOUT_CUDA();
#if defined(CONTACTGRID_HAVE_CUDA)
  using Real = TypeParam;
  const ShapeScene s = make_scene("mixed", 61, 700, 0.5, 12.0);
  Engine<Real> cpu({.backend = Backend::cpu, .fields = Fields::full});
  Engine<Real> gpu({.backend = Backend::cuda, .fields = Fields::full});
  const Contacts<Real> a = cpu.detect(s.view());
  {
    DeviceScene d(s);
    expect_identical(a, gpu.detect_device(d.v), "detect_device with shapes");
    EXPECT_EQ(gpu.stats().ellipsoids, cpu.stats().ellipsoids);
  }
  // bad rows on the device: the host path's InputError text
  for (int fault = 0; fault < 3; ++fault) {
    ShapeScene bad = s;
    auto ellipsoid_from = [&](std::size_t i) {
      while (bad.shape[i] != Shape::ellipsoid) ++i;
      return i;
    };
    if (fault == 0) bad.axes[ellipsoid_from(40)].x = -1;
    if (fault == 1) bad.q[ellipsoid_from(70)] = {0, 0, 0, 0};
    if (fault == 2) bad.shape[90] = static_cast<Shape>(9);
    std::string host_text, device_text;
    try {
      cpu.detect(bad.view());
    } catch (const InputError& e) {
      host_text = e.what();
    }
    DeviceScene d(bad);
    try {
      gpu.detect_device(d.v);
    } catch (const InputError& e) {
      device_text = e.what();
    }
    EXPECT_FALSE(host_text.empty()) << fault;
    EXPECT_EQ(host_text, device_text) << fault;
  }
#endif
}

}  // namespace
}  // namespace cg::test
