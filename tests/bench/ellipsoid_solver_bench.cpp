// Host timing of the ellipsoid narrow phase (kernels/core/ellipsoid_contact.hpp); not a test.
//   g++ -std=c++20 -O2 -ffp-contract=off -I kernels tests/bench/ellipsoid_solver_bench.cpp -o /tmp/eb &&
//   /tmp/eb
// Candidate pairs as a uniform random scene's broad phase hands them over: semi-axes U[0.5, 1], random
// orientations, centre distance d with density ∝ d² on [0, ρa + ρb] (bounding spheres overlap). A
// 0.4-contacts-per-body scene has the same per-candidate depth distribution; only the candidate count
// scales with density. Reports, per precision: the PW filter alone, the solve on the pairs that pass
// (default settings and cheaper start sets, with the minima they miss), the full ellipsoid_contact() per
// candidate, and the sphere–ellipsoid path.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "core/ellipsoid_contact.hpp"

using namespace cg;

template <class Real>
std::vector<std::pair<Ellipsoid<Real>, Ellipsoid<Real>>> candidates(int n, double lo, double hi,
                                                                    unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> ax(lo, hi), u(0, 1);
  std::normal_distribution<double> g;
  auto quat = [&] {
    double w = g(rng), x = g(rng), y = g(rng), z = g(rng), s = std::sqrt(w * w + x * x + y * y + z * z);
    return Quat<Real>{Real(w / s), Real(x / s), Real(y / s), Real(z / s)};
  };
  std::vector<std::pair<Ellipsoid<Real>, Ellipsoid<Real>>> out;
  for (int i = 0; i < n; ++i) {
    const Vec3<Real> ea{Real(ax(rng)), Real(ax(rng)), Real(ax(rng))},
        eb{Real(ax(rng)), Real(ax(rng)), Real(ax(rng))};
    const double rho = std::max({ea.x, ea.y, ea.z}) + std::max({eb.x, eb.y, eb.z});
    const double d = rho * std::cbrt(u(rng));  // density ∝ d²
    double x = g(rng), y = g(rng), z = g(rng), s = std::sqrt(x * x + y * y + z * z);
    const Vec3<Real> cb{Real(0.25), Real(-0.5), Real(0.75)};
    const Vec3<Real> ca{Real(cb.x + d * x / s), Real(cb.y + d * y / s), Real(cb.z + d * z / s)};
    out.push_back({make_ellipsoid(ca, ea, quat()), make_ellipsoid(cb, eb, quat())});
  }
  return out;
}

template <class F>
double seconds(F&& f) {
  const auto t0 = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

template <class Real>
void run(const char* name, double lo, double hi) {
  const int n = 20000;
  const auto pairs = candidates<Real>(n, lo, hi, 42);
  volatile double sink = 0;
  // 1. the PW filter
  std::vector<PerramWertheim<Real>> pw(n);
  const double t_pw = seconds([&] {
    for (int i = 0; i < n; ++i) pw[i] = perram_wertheim(pairs[i].first, pairs[i].second);
  });
  long pw_it = 0;
  int passed = 0;
  for (auto& p : pw) {
    pw_it += p.iterations;
    passed += pw_may_touch(p);
  }
  std::printf(
      "%s semi-axes U[%.2g,%.2g]: %d candidates, PW passes %d (%.0f%%), PW %.2f M/s, iterations mean %.1f\n",
      name, lo, hi, n, passed, 100.0 * passed / n, n / t_pw * 1e-6, double(pw_it) / n);
  // 2. the solve on the pairs that pass: the default (11 starts + screen of 3), then cheaper start sets;
  //    "worse minimum" counts pairs whose minimum is above the default's (missed global minima)
  struct Config {
    int starts, screen;
  };
  std::vector<EllipsoidContact<Real>> full(n);
  for (Config cfg : {Config{11, 3}, Config{11, 0}, Config{8, 0}, Config{5, 0}, Config{1, 0}}) {
    SolverSettings<Real> st;
    st.starts = cfg.starts;
    st.screen = cfg.screen;
    std::vector<EllipsoidContact<Real>> res(n);
    const double t = seconds([&] {
      for (int i = 0; i < n; ++i)
        if (pw_may_touch(pw[i])) res[i] = ellipsoid_pair_contact(pairs[i].first, pairs[i].second, pw[i], st);
    });
    if (cfg.starts == 11 && cfg.screen == 3) full = res;
    long evals = 0;
    int mx = 0, nonconv = 0, fb = 0, miss = 0, wrong_decision = 0;
    for (int i = 0; i < n; ++i) {
      if (!pw_may_touch(pw[i])) continue;
      evals += res[i].iterations;
      mx = std::max(mx, res[i].iterations);
      nonconv += !res[i].converged;
      fb += res[i].fallback;
      const double s = 2.0 * hi;
      if (std::abs(double(res[i].geometry.distance - full[i].geometry.distance)) > 1e-5 * s) ++miss;
      if ((res[i].geometry.distance <= 0) != (full[i].geometry.distance <= 0)) ++wrong_decision;
      sink = sink + double(res[i].geometry.distance);
    }
    std::printf(
        "  solve, %2d starts + screen %d: %.3f M solves/s (%.2f µs), evaluations mean %.1f max %d, "
        "non-converged %d, fallback %d, worse minimum than the default %d, other decision %d\n",
        cfg.starts, cfg.screen, passed / t * 1e-6, t / passed * 1e6, double(evals) / passed, mx, nonconv, fb,
        miss, wrong_decision);
  }
  // 3. the whole entry point per candidate (filter + solve), default settings
  int contacts = 0;
  const double t_all = seconds([&] {
    for (int i = 0; i < n; ++i) contacts += ellipsoid_contact(pairs[i].first, pairs[i].second).in_contact;
  });
  std::printf("  ellipsoid_contact() per candidate: %.3f M/s; contacts %d (%.0f%% of candidates)\n",
              n / t_all * 1e-6, contacts, 100.0 * contacts / n);
  // 4. sphere–ellipsoid
  std::vector<Sphere<Real>> spheres;
  for (auto& p : pairs)
    spheres.push_back({p.first.centre.x, p.first.centre.y, p.first.centre.z, p.first.semi_axes.x});
  long it = 0;
  const double t_se = seconds([&] {
    for (int i = 0; i < n; ++i) {
      const auto c = sphere_ellipsoid_contact(spheres[i], pairs[i].second, true);
      it += c.iterations;
      sink = sink + double(c.geometry.distance);
    }
  });
  std::printf("  sphere_ellipsoid_contact(): %.3f M/s, root-find iterations mean %.1f\n", n / t_se * 1e-6,
              double(it) / n);
}

int main() {
  run<float>("fp32", 0.5, 1.0);
  run<double>("fp64", 0.5, 1.0);
  run<float>("fp32", 0.1, 1.0);
  run<double>("fp64", 0.1, 1.0);
  return 0;
}
