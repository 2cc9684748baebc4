// The start set of the ellipsoid solve (kernels/core/ellipsoid_solve.hpp): the stress regressions it must
// find the global minimum of, its runs taken in batches (the device's WarpRuns) giving the serial bits,
// and a starved solver flagged, each against the exact long-double reference (ellipsoid_pairs.hpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "core/contact.hpp"
#include "core/ellipsoid_contact.hpp"
#include "core/quat.hpp"
#include "core/shape_narrow.hpp"
#include "ellipsoid_pairs.hpp"
#include "reference/ellipsoid_reference.hpp"

namespace cg::test {
namespace {

TYPED_TEST_SUITE(EllipsoidContactTest, Reals);

// Regression: deep-overlap pairs from stress runs against the reference (25 500 pairs) that the 8 fixed
// starts alone missed: the first three because every start's local minimum had n·(a − b) slightly < 0
// (the reflection step, f(−n) = f(n) + 2 n·(a − b), finds them), the last three because the global
// minimum was the other member of a near-antipodal pair (the antipode run of the best finds them), the
// last two because only a start on a bisector of the two thinnest axes reaches the global basin.
TYPED_TEST(EllipsoidContactTest, StressRegressionsFindTheGlobalMinimum) {
  using Real = TypeParam;
  struct Case {
    double ca[3], ea[3], qa[4], eb[3], qb[4];
  };
  const Case cases[] = {
      {{0.049542257354311621, 0.14817446361617703, 0.13524127485246873},
       {0.39890412320856294, 0.1, 1},
       {0.61743728553071586, 0.090915736755512955, 0.11927972182337954, -0.77219031022695495},
       {0.1, 1, 0.94841511613814156},
       {0.63802047908912074, 0.48402020116488426, 0.59883563543024076, 0.0070848335233370677}},
      {{0.000484219599129046, 0.043074411189862709, -0.038518702578834656},
       {0.35479756170210119, 1, 0.033333333333333333},
       {-0.18465566757782412, -0.53103708767443802, 0.20446890012396995, -0.80130790887631542},
       {0.033333333333333333, 1, 0.82841134966793206},
       {-0.11978901692020688, -0.87953959017022787, -0.26293513889727227, -0.3780553047922357}},
      {{-0.0065130036549601944, 0.0038105383137064957, -0.0095967166369569715},
       {1, 0.033333333333333333, 0.74944884971445258},
       {0.063627517368558956, 0.68436826300371889, 0.58700521570917941, 0.42780427342069188},
       {1, 0.033333333333333333, 0.99070098532038287},
       {-0.05646489502143727, 0.65540444996466629, 0.39037977588006711, -0.64409654026439223}},
      // the antipode of the best (both minima of a near-antipodal pair have n·(a − b) ≥ 0)
      {{-0.084109126343144436, -0.058795716452977355, 0.066277818092687513},
       {0.1, 0.78659757859572332, 1},
       {0.13126628149967398, 0.18293575005248197, -0.84460755576860769, 0.48573835697066636},
       {1, 0.15171741778757208, 0.1},
       {-0.19366645094002125, 0.33414988573635879, -0.18373323124907187, 0.90392436596069792}},
      {{-0.071793084780539473, -0.032942741979032873, 0.085427981531328342},
       {0.01, 1, 0.73627998821418961},
       {-0.17444306193123776, 0.50071558519065729, -0.22773204020460522, -0.81669556063167137},
       {0.49742891350542395, 1, 0.01},
       {-0.46034748719661761, 0.61151979069887819, 0.61981178524950487, -0.17308115865449328}},
      {{-0.10492550741794275, 0.41262328293926287, 0.097118498565802638},
       {1, 0.36154376727745097, 0.01},
       {-0.75519479931300515, -0.24227898027168746, -0.34310920299637504, 0.50324724105383178},
       {1, 0.044398813756797779, 0.01},
       {-0.44177014942373927, 0.43186847900398134, 0.65359029793764367, -0.43720530001670493}},
      // a basin reached only from a bisector of the two thinnest axes
      {{-0.037560377134184059, 0.0082757546250927464, -0.067666803393867797},
       {0.58275192939414588, 1, 0.033333333333333333},
       {-0.80319333560130446, 0.38242762229910854, 0.018271127324890876, -0.45639428705295876},
       {1, 0.033333333333333333, 0.6866074387140858},
       {-0.27217029700598439, 0.78872783206935249, 0.1106557007252128, 0.53998801120382811}},
      {{-0.16424703621346728, -0.10398868594066041, -0.053995465732879118},
       {0.033333333333333333, 1, 0.89207983420609527},
       {-0.4512197183440379, -0.51653229081008389, -0.72679728461896631, -0.036889909169193526},
       {1, 0.033333333333333333, 0.94147190868366704},
       {-0.70679441763114437, 0.2642834297095179, -0.65111284570600969, -0.081535158938016772}},
  };
  Stats st;
  st.name = tag<Real>("stress regressions");
  for (const Case& c : cases) {
    const Body<Real> a{{Real(c.ca[0]), Real(c.ca[1]), Real(c.ca[2])},
                       {Real(c.ea[0]), Real(c.ea[1]), Real(c.ea[2])},
                       {Real(c.qa[0]), Real(c.qa[1]), Real(c.qa[2]), Real(c.qa[3])}};
    const Body<Real> b{{0, 0, 0},
                       {Real(c.eb[0]), Real(c.eb[1]), Real(c.eb[2])},
                       {Real(c.qb[0]), Real(c.qb[1]), Real(c.qb[2]), Real(c.qb[3])}};
    check_against_reference(a, b, solve(a, b), st, 20000);
  }
  st.print();
}

// The start set's runs are functions of their starts alone (ellipsoid_solve.hpp: newton_run), so a
// provider that runs every start of a batch before taking any — what the device's warp kernel does,
// one start per lane (cuda/narrow_shapes.cuh: WarpRuns) — gives SerialRuns' bits and counts. Checked here on
// the host with such a provider, over pairs that run the whole set: deep and crossed overlaps at
// aspects 2–20, the certificates on and off, and a starved cap (the safety net's batch).
struct BatchFirstRuns {
  mutable int unused = 0;  // runs made that the solve did not take
  template <class Start, class Run, class More, class Take>
  void batch(int count, const Start& start, const Run& run, const More& more, const Take& take) const {
    using Result = decltype(run(start(0)));
    std::vector<Result> res(static_cast<std::size_t>(count));
    std::vector<bool> valid(static_cast<std::size_t>(count));
    for (int j = 0; j < count; ++j) {
      const auto s = start(j);
      valid[j] = !is_zero(s);
      if (valid[j]) res[j] = run(s);
    }
    int j = 0;
    for (; j < count && more(); ++j)
      if (valid[j]) take(res[j]);
    for (; j < count; ++j) unused += valid[j] ? 1 : 0;
  }
};

TYPED_TEST(EllipsoidContactTest, RunsTakenInBatchesGiveTheSerialBits) {
  using Real = TypeParam;
  std::mt19937_64 rng(12000);
  std::uniform_real_distribution<double> u(-0.9, 0.9);
  SolverSettings<Real> certify, whole, starved;
  whole.certify = false;
  starved.max_iterations = 2;
  int pairs = 0, fallbacks = 0, unused = 0;
  for (double aspect : {2.0, 5.0, 20.0})
    for (int i = 0; i < 60; ++i) {
      Body<Real> a{{}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
      Body<Real> b{
          {Real(u(rng)), Real(u(rng)), Real(u(rng))}, random_axes<Real>(rng, aspect), random_quat<Real>(rng)};
      const Ellipsoid<Real> ea = engine_body(a), eb = engine_body(b);
      const PerramWertheim<Real> pw = perram_wertheim(ea, eb);
      for (const SolverSettings<Real>* st : {&certify, &whole, &starved}) {
        const EllipsoidContact<Real> s = ellipsoid_pair_contact(ea, eb, pw, *st);
        const BatchFirstRuns batched;
        const EllipsoidContact<Real> w = ellipsoid_pair_contact(ea, eb, pw, *st, batched);
        const std::string what = "aspect " + std::to_string(aspect) + " pair " + std::to_string(i);
        EXPECT_EQ(s.geometry.distance, w.geometry.distance) << what;
        EXPECT_EQ(s.geometry.normal_on_b.x, w.geometry.normal_on_b.x) << what;
        EXPECT_EQ(s.geometry.normal_on_b.y, w.geometry.normal_on_b.y) << what;
        EXPECT_EQ(s.geometry.normal_on_b.z, w.geometry.normal_on_b.z) << what;
        EXPECT_EQ(s.iterations, w.iterations) << what;
        EXPECT_EQ(s.converged, w.converged) << what;
        EXPECT_EQ(s.fallback, w.fallback) << what;
        ++pairs;
        fallbacks += s.fallback;
        unused += batched.unused;
      }
    }
  std::printf("[ellipsoid] %-28s %d solves, %d runs made and not taken, %d fallbacks\n",
              tag<Real>("runs in batches").c_str(), pairs, unused, fallbacks);
  EXPECT_GT(unused, 0) << "some batch should stop at a certified minimum";
  EXPECT_GT(fallbacks, 0) << "the starved cap should reach the safety net's batch";
}

// Never silently wrong about convergence: with an iteration cap too small to converge (1 evaluation per
// start, 4 in the continuation), a pair reports converged = false with `fallback` set. (Converged then
// means a local minimum only: with starved starts it need not be the global one, and it is not checked.)
TYPED_TEST(EllipsoidContactTest, StarvedSolverIsFlagged) {
  using Real = TypeParam;
  std::mt19937_64 rng(10000);
  std::uniform_real_distribution<double> u(0, 0.8);
  SolverSettings<Real> starved;
  starved.max_iterations = 1;
  int flagged = 0, converged_anyway = 0;
  for (int i = 0; i < 40; ++i) {
    Body<Real> b{{}, random_axes<Real>(rng, 20), random_quat<Real>(rng)};
    Body<Real> a{{}, random_axes<Real>(rng, 20), random_quat<Real>(rng)};
    const Vec3<double> d = random_unit(rng);
    const double len = u(rng) * double(scale_of(a, b));
    a.centre = {Real(len * d.x), Real(len * d.y), Real(len * d.z)};
    const Ellipsoid<Real> ea = engine_body(a), eb = engine_body(b);
    const EllipsoidContact<Real> c = ellipsoid_pair_contact(ea, eb, perram_wertheim(ea, eb), starved);
    if (!c.converged) {
      ++flagged;
      EXPECT_TRUE(c.fallback);
      continue;
    }
    ++converged_anyway;
    EXPECT_TRUE(c.fallback);  // every start stopped unconverged, so the safety net ran
  }
  std::printf(
      "[ellipsoid] %-28s max_iterations 1: %d flagged non-converged, %d converged by the continuation\n",
      tag<Real>("starved solver").c_str(), flagged, converged_anyway);
  EXPECT_GT(flagged, 0);
}

}  // namespace
}  // namespace cg::test
