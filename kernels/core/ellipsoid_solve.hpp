#pragma once
// The contact solve of two ellipsoids: the global minimum of f over the unit sphere by damped Newton
// from a fixed ordered start set, with its safety net (core/ellipsoid_contact.hpp: the overview).
#include "core/ellipsoid_certificate.hpp"
#include "core/perram_wertheim.hpp"

namespace cg {

// ---------------------------------------------------------------------------------------------------
// The contact solve.

namespace detail {

// f, its tangential gradient and its Riemannian Hessian at n, in the tangent basis (t1, t2).
template <class Real>
struct Evaluation {
  Vec3<Real> n, t1, t2;
  Real f, g1, g2, h11, h12, h22;
};

// Adds h(n), ∇h·t_i and t_iᵀ ∇²h t_j of one ellipsoid: with v = Rᵀn, w = D v, h = |w|,
// ∇h = R D² v / h and ∇²h = R (D² − D²v vᵀD² / h²) Rᵀ / h.
template <class Real>
CG_HD void add_body(const Ellipsoid<Real>& e, Evaluation<Real>& ev) {
  const Vec3<Real> d = e.semi_axes;
  const Vec3<Real> w = hadamard(d, mul_transpose(e.rotation, ev.n));
  const Vec3<Real> u1 = hadamard(d, mul_transpose(e.rotation, ev.t1));
  const Vec3<Real> u2 = hadamard(d, mul_transpose(e.rotation, ev.t2));
  const Real h = cg_sqrt(dot(w, w)), inv = Real(1) / h;
  const Real g1 = dot(w, u1) * inv, g2 = dot(w, u2) * inv;
  ev.f += h;
  ev.g1 += g1;
  ev.g2 += g2;
  ev.h11 += (dot(u1, u1) - g1 * g1) * inv;
  ev.h12 += (dot(u1, u2) - g1 * g2) * inv;
  ev.h22 += (dot(u2, u2) - g2 * g2) * inv;
}

template <class Real>
CG_HD Evaluation<Real> evaluate(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b, Vec3<Real> r,
                                Vec3<Real> n) {
  Evaluation<Real> ev{};
  ev.n = n;
  plane_space(n, ev.t1, ev.t2);
  add_body(a, ev);  // h_A(−n) = h_A(n), and ∇²h_A is even: A enters exactly as B does
  add_body(b, ev);
  ev.f -= dot(n, r);
  ev.g1 -= dot(ev.t1, r);
  ev.g2 -= dot(ev.t2, r);
  // Riemannian Hessian on the sphere: Tᵀ∇²f T − (n·∇f) I, and n·∇f = f (Euler, f is 1-homogeneous).
  ev.h11 -= ev.f;
  ev.h22 -= ev.f;
  return ev;
}

template <class Real>
struct LocalResult {
  Vec3<Real> n;
  Real f, grad;
  int evaluations;
  bool converged;
};

// Damped Newton from n0: the 2×2 Riemannian Hessian is shifted to be positive definite (λmin ≥ δ), the
// step is capped to a trust radius Δ (radians) that halves on rejection and doubles on success, and the
// new point is normalize(n + s1 t1 + s2 t2). A step is accepted if it lowers f, or — where the change of
// f is below its rounding (near the minimum in fp32) — if it lowers the gradient without raising f
// beyond rounding.
template <class Real>
CG_HD LocalResult<Real> local_minimise(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b, Vec3<Real> r,
                                       Vec3<Real> n0, Real scale, Real tolerance, int max_evaluations) {
  const Real eps = std::numeric_limits<Real>::epsilon();
  const Real gtol = tolerance * scale;
  const Real f_noise = Real(16) * eps * (scale + cg_sqrt(dot(r, r)));
  const Real delta_min = Real(1e-3) * scale;
  Evaluation<Real> ev = evaluate(a, b, r, n0);
  int evaluations = 1;
  Real radius = Real(0.5);
  Real grad = cg_sqrt(ev.g1 * ev.g1 + ev.g2 * ev.g2);
  bool converged = grad <= gtol;
  while (!converged && evaluations < max_evaluations) {
    const Real half_tr = Real(0.5) * (ev.h11 + ev.h22), half_diff = Real(0.5) * (ev.h11 - ev.h22);
    const Real lmin = half_tr - cg_sqrt(half_diff * half_diff + ev.h12 * ev.h12);
    const Real mu = lmin < delta_min ? delta_min - lmin : Real(0);
    const Real p11 = ev.h11 + mu, p22 = ev.h22 + mu, det = p11 * p22 - ev.h12 * ev.h12;
    Real s1 = -(p22 * ev.g1 - ev.h12 * ev.g2) / det;
    Real s2 = -(p11 * ev.g2 - ev.h12 * ev.g1) / det;
    const Real len = cg_sqrt(s1 * s1 + s2 * s2);
    if (len > radius) {
      s1 *= radius / len;
      s2 *= radius / len;
    }
    const Vec3<Real> trial = normalized(ev.n + s1 * ev.t1 + s2 * ev.t2);
    const Evaluation<Real> next = evaluate(a, b, r, trial);
    ++evaluations;
    const Real next_grad = cg_sqrt(next.g1 * next.g1 + next.g2 * next.g2);
    const bool accept = next.f < ev.f - f_noise || (next.f <= ev.f + f_noise && next_grad < grad);
    if (accept) {
      ev = next;
      grad = next_grad;
      converged = grad <= gtol;
      radius = cg_min(Real(2) * radius, Real(1));
    } else {
      radius *= Real(0.25);
      if (radius < Real(4) * eps) break;  // stalled: no representable progress
    }
  }
  return {ev.n, ev.f, grad, evaluations, converged};
}

// Puts a start on the side of a − b (where the global minimiser lies); a zero vector is left alone.
template <class Real>
CG_HD Vec3<Real> towards(Vec3<Real> v, Vec3<Real> r) {
  return dot(v, r) < Real(0) ? -v : v;
}

// One Newton run of the start set: the start put towards a − b, damped Newton, and a minimum on the far
// side of a − b reflected — f(−n) = f(n) + 2 n·(a − b) < f(n), so it is never global; Newton continues
// from its mirror image. `evaluations` counts both legs. A run is a function of its start alone (no run
// stops at a minimum another found), so the runs of one solve may go one after the other or side by
// side (SerialRuns, and the device's warp of lanes) with the same bits.
template <class Real>
CG_HD LocalResult<Real> newton_run(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b, Vec3<Real> r,
                                   Vec3<Real> start, Real scale, Real tolerance, int max_evaluations) {
  LocalResult<Real> res = local_minimise(a, b, r, towards(start, r), scale, tolerance, max_evaluations);
  if (dot(res.n, r) < Real(0)) {
    const int first = res.evaluations;
    res = local_minimise(a, b, r, -res.n, scale, tolerance, max_evaluations);
    res.evaluations += first;
  }
  return res;
}

// The 13 extra directions of the safety net: the 3 world axes, the 4 cube diagonals, the 6 face
// diagonals (up to sign).
template <class Real>
CG_HD Vec3<Real> extra_start(int i) {
  const Real s3 = Real(0.57735026918962576451), s2 = Real(0.70710678118654752440);
  switch (i) {
    case 0:
      return {Real(1), Real(0), Real(0)};
    case 1:
      return {Real(0), Real(1), Real(0)};
    case 2:
      return {Real(0), Real(0), Real(1)};
    case 3:
      return {s3, s3, s3};
    case 4:
      return {s3, s3, -s3};
    case 5:
      return {s3, -s3, s3};
    case 6:
      return {-s3, s3, s3};
    case 7:
      return {s2, s2, Real(0)};
    case 8:
      return {s2, -s2, Real(0)};
    case 9:
      return {s2, Real(0), s2};
    case 10:
      return {s2, Real(0), -s2};
    case 11:
      return {Real(0), s2, s2};
    default:
      return {Real(0), s2, -s2};
  }
}

}  // namespace detail

// How a solve runs a batch of its Newton runs (newton_run from start j, j < count) and takes their
// results in start order: before each, more() says whether the solve still wants one (the start set
// stops at a certified minimum); start(j) gives start j (a zero vector: none, skipped); run(s) is the
// run from s; take(result) folds it in. SerialRuns runs start j only when it is wanted (the host; the
// device's one-thread-per-pair kernels); the device's lane-group-per-pair kernel runs the batch on its
// lanes at once and hands the results over in the same order (cuda/narrow_shapes.cuh: WarpRuns) — the same
// bits, the same counts (a run no one takes is not counted).
template <class Real>
CG_HD bool is_zero(const Vec3<Real>& v) {
  return v.x == Real(0) && v.y == Real(0) && v.z == Real(0);
}
struct SerialRuns {
  template <class Start, class Run, class More, class Take>
  CG_HD void batch(int count, const Start& start, const Run& run, const More& more, const Take& take) const {
    for (int j = 0; j < count; ++j) {
      if (!more()) return;
      const auto s = start(j);
      if (!is_zero(s)) take(run(s));
    }
  }
};

// The contact at a given normal n (from B towards A; the solve's minimiser): the support points,
// local points, distance and positions. The solve ends with it, and the device's fill pass calls it
// on the stored minimiser: the same bits without solving again.
template <class Real>
CG_HD void contact_at_normal(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b, Vec3<Real> n,
                             EllipsoidContact<Real>& out) {
  const Vec3<Real> r = a.centre - b.centre;
  // Support points in the body frames: ∇h(u) = R D² Rᵀu / |D Rᵀu|; A's is taken at −n.
  const Vec3<Real> va = detail::hadamard(a.semi_axes, mul_transpose(a.rotation, n));
  const Vec3<Real> vb = detail::hadamard(b.semi_axes, mul_transpose(b.rotation, n));
  const Real ha = cg_sqrt(dot(va, va)), hb = cg_sqrt(dot(vb, vb));
  out.local_point_a = (Real(-1) / ha) * detail::hadamard(a.semi_axes, va);
  out.local_point_b = (Real(1) / hb) * detail::hadamard(b.semi_axes, vb);
  out.geometry.normal_on_b = n;
  out.geometry.distance = dot(n, r) - (ha + hb);
  out.geometry.position_on_a = a.centre + mul(a.rotation, out.local_point_a);
  out.geometry.position_on_b = b.centre + mul(b.rotation, out.local_point_b);
}

// What SolveScope::first_start_cheap knew of a pair it left incomplete — the first start's run and the
// PW filter's value and band — so that SolveScope::first_start (the settle pass) goes on from it with the
// inner-ellipsoid certificate instead of running the filter and the start again: the same best, the same
// counted evaluations, so the same bits and flags as running them again (the whole solve still starts
// afresh). 36 bytes in fp32.
template <class Real>
struct FirstStart {
  detail::LocalResult<Real> result;
  Real pw_value, pw_band;
};

// The general solve (no dispatch on spheres): see the file comment. `pw` is the result of
// perram_wertheim(a, b) (the caller has it from the filter). SolveScope::first_start* stops after the
// first start unless it is certified (and consistent with the PW sign): `complete` false, no geometry;
// where it is certified, the answer is the whole solve's, bit for bit. The scope is a template
// parameter so that the first-start kernel does not carry the whole set's code (registers, stack).
// `carry` (FirstStart, optional): first_start_cheap fills it where it leaves the pair incomplete;
// first_start takes the first start's run from it instead of running it (`pw`: its value and band).
template <SolveScope Scope = SolveScope::whole, class Real, class Runs = SerialRuns>
CG_HD EllipsoidContact<Real> ellipsoid_pair_contact(const Ellipsoid<Real>& a, const Ellipsoid<Real>& b,
                                                    const PerramWertheim<Real>& pw,
                                                    const SolverSettings<Real>& settings = {},
                                                    const Runs& runs = {},
                                                    FirstStart<Real>* carry = nullptr) {
  const Vec3<Real> r = a.centre - b.centre;
  const bool coincident = is_zero(r);
  const Real scale = detail::max_axis(a.semi_axes) + detail::max_axis(b.semi_axes);
  const Real rlen = cg_sqrt(dot(r, r));
  EllipsoidContact<Real> out{};
  out.pw = pw.value;
  out.converged = false;
  out.fallback = false;

  // A later candidate wins only if lower by more than the rounding of f: ties (coincident centres,
  // symmetric pairs) keep the earlier start on every machine.
  const Real f_tie = Real(4) * std::numeric_limits<Real>::epsilon() * (scale + rlen);
  detail::LocalResult<Real> best{};
  bool have = false;
  bool cert = false, cert_stale = true;  // the certificate of `best` (below), recomputed when it changes
  auto run = [&](Vec3<Real> start) {
    return detail::newton_run(a, b, r, start, scale, settings.tolerance, settings.max_iterations);
  };
  auto take = [&](const detail::LocalResult<Real>& res) {
    out.iterations += res.evaluations;
    if (!have || res.f < best.f - f_tie) {
      best = res;
      have = true;
      cert_stale = true;
    }
  };
  auto always = [] { return true; };
  // The certificates of globality (core/ellipsoid_certificate.hpp): a negative minimum (separated),
  // two inscribed balls, an inner ellipsoid of A ⊕ (−B), in that order (the third costs about five
  // evaluations of f; SolveScope::first_start_cheap leaves it out), once per new best. Each proves
  // min f ≥ f(n) − |P∇f(n)|. Separated and shallow pairs — nearly every contact of a packing — and
  // nearly all deep overlaps take one start; what is left runs the whole set.
  const Real f_noise = Real(16) * std::numeric_limits<Real>::epsilon() * (scale + rlen);
  auto certified = [&] {
    if (cert_stale) {
      cert_stale = false;
      cert = settings.certify && have && best.converged &&
             (best.f < Real(0) || best.f + f_noise <= detail::inscribed_ball_reach(a, b, best.n));
      if constexpr (Scope != SolveScope::first_start_cheap)
        if (!cert && settings.certify && have && best.converged)
          cert = detail::inner_ellipsoid_certificate(a, b, best.n, best.f, f_noise);
    }
    return cert;
  };
  const Vec3<Real> first = coincident ? Vec3<Real>{Real(1), Real(0), Real(0)} : pw.normal;
  auto keep_first = [&] {  // first_start_cheap, incomplete: what first_start goes on from
    if constexpr (Scope == SolveScope::first_start_cheap)
      if (carry) *carry = {best, pw.value, pw.band};
  };
  if constexpr (Scope != SolveScope::whole) {
    if (Scope == SolveScope::first_start && carry)
      take(carry->result);
    else
      take(run(first));
    if (!certified()) {
      out.complete = false;  // the second pass runs the whole solve
      keep_first();
      return out;
    }
  } else {
    // The fixed ordered start set, up to the first certified minimum.
    const int nstarts = settings.starts < 1 ? 1 : (settings.starts > 11 ? 11 : settings.starts);
    auto start_set = [&](int s) -> Vec3<Real> {
      const Vec3<Real> none{};
      if (s == 0) return first;
      if (s == 1) return coincident ? none : (Real(1) / rlen) * r;  // (1,0,0) already ran
      if (s < 8) return s < 5 ? column(a.rotation, s - 2) : column(b.rotation, s - 5);
      Vec3<Real> v;
      if (s < 10) {  // the two bisectors of the thinnest axes of A and B
        const Vec3<Real> ta = column(a.rotation, detail::min_index(a.semi_axes));
        const Vec3<Real> tb = detail::towards(column(b.rotation, detail::min_index(b.semi_axes)), ta);
        v = s == 8 ? ta + tb : ta - tb;
      } else {  // the common normal of the longest axes (crossed needles)
        v = cross(column(a.rotation, detail::max_index(a.semi_axes)),
                  column(b.rotation, detail::max_index(b.semi_axes)));
      }
      return dot(v, v) < Real(1e-6) ? none : detail::normalized(v);
    };
    // The screen: f (value only) at the 4 cube diagonals and 6 face diagonals of each body's frame (up
    // to sign, put towards a − b); Newton from the `screen` lowest. These in-between directions reach
    // basins that no axis start does (two comparable thin axes, one body's thin axis tilted by the other).
    // They run only when no start of the set gave a certified minimum, and are taken in the same batch,
    // after the set: a lane group runs set and screen side by side (one round of 16 lanes, not two:
    // the hard pass waits on its slowest pair's chain of rounds), SerialRuns computes the screen only
    // when the set is through uncertified. The same runs taken in the same order as one batch after the
    // other, so the same bits.
    const int keep = settings.screen > 4 ? 4 : (settings.screen > 0 ? settings.screen : 0);
    Real top_f[4];
    Vec3<Real> top_n[4];
    bool screened = false;
    auto screen = [&] {
      screened = true;
      int count = 0;
      for (int i = 0; i < 20; ++i) {
        const Mat3<Real>& rot = i < 10 ? a.rotation : b.rotation;
        const Vec3<Real> n = detail::towards(mul(rot, detail::extra_start<Real>(3 + i % 10)), r);
        const Real fv = detail::support_value(a, n) + detail::support_value(b, n) - dot(n, r);
        int pos = count < keep ? count : keep;
        while (pos > 0 && fv < top_f[pos - 1]) {
          if (pos < keep) {
            top_f[pos] = top_f[pos - 1];
            top_n[pos] = top_n[pos - 1];
          }
          --pos;
        }
        if (pos < keep) {
          top_f[pos] = fv;
          top_n[pos] = n;
          if (count < keep) ++count;
        }
      }
    };
    auto set_then_screen = [&](int s) -> Vec3<Real> {
      if (s < nstarts) return start_set(s);
      if (!screened) screen();
      return top_n[s - nstarts];
    };
    int asked = 0;  // the batch asks `more` once before each start, in order
    auto more = [&] {
      const int s = asked++;
      if (s < nstarts) return !certified();
      if (s == nstarts) {
        if (certified()) return false;
        out.iterations += 20 / 4;  // the screen's 20 value-only evaluations ≈ 5 full ones
      }
      return true;  // every screened start is taken
    };
    runs.batch(nstarts + keep, set_then_screen, run, more, take);
    // The antipode of the best: where a − b is short against the bodies, minima come in near-antipodal
    // pairs (f(−n) = f(n) + 2 n·r) and the deeper one of a pair may be the one no start reached.
    for (int round = 0; round < 2 && !certified(); ++round) {
      const detail::LocalResult<Real> res =
          detail::local_minimise(a, b, r, -best.n, scale, settings.tolerance, settings.max_iterations);
      out.iterations += res.evaluations;
      if (!(res.f < best.f - f_tie)) break;
      best = res;
      cert_stale = true;
    }
  }  // whole set

  // The safety net: the PW sign is exact (a global statement), min f must agree with it beyond rounding.
  const Real eps = std::numeric_limits<Real>::epsilon();
  const Real f_band = Real(64) * eps * (scale + rlen) + settings.tolerance * scale;
  const bool pw_overlap = pw.value<Real(1) - pw.band, pw_apart = pw.value> Real(1) + pw.band;
  const bool inconsistent = (pw_overlap && best.f < -f_band) || (pw_apart && best.f > f_band);
  if constexpr (Scope != SolveScope::whole) {
    if (inconsistent || !best.converged) {
      out.complete = false;
      keep_first();
      return out;
    }
  } else if (inconsistent || !best.converged) {
    out.fallback = true;
    runs.batch(
        13, [](int i) { return detail::extra_start<Real>(i); }, run, always, take);
    if (!best.converged)  // continuation
      take(detail::newton_run(a, b, r, best.n, scale, settings.tolerance, 4 * settings.max_iterations));
  }
  out.converged = best.converged;

  Vec3<Real> n = best.n;
  if (coincident) {  // canonical sign: the first non-zero component positive
    const bool flip = n.x != Real(0) ? n.x < Real(0) : (n.y != Real(0) ? n.y < Real(0) : n.z < Real(0));
    if (flip) n = -n;
  }
  contact_at_normal(a, b, n, out);
  return out;
}

}  // namespace cg
