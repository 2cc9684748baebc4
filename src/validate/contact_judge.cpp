// The judge's math (see contact_judge.hpp): support functions, f, its global minimisation by samples
// plus Newton on the sphere with the analytic Hessian, and the optimality conditions of one answer.
//
// Newton on the unit sphere: f is 1-homogeneous, so ∇f·n = f and the Euclidean Hessian H satisfies
// H n = 0; with ∇²h(u) = (Mᵀ M − s(u) s(u)ᵀ) / h(u) (M = D Rᵀ), H(n) = ∇²h_A(−n) + ∇²h_B(n), and
// the Riemannian Hessian in a tangent basis (e1, e2) is e_iᵀ H e_j − f δ_ij. Each Newton step solves
// that 2×2 system (shifted to be positive definite), moves n by at most 0.5 rad and backtracks on f.
#include "validate/contact_judge.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace cg::judge {
namespace {

constexpr LD kPi = 3.14159265358979323846264338327950288L;

LD norm(V v) { return std::sqrt(dot(v, v)); }
V unit(V v) { return (1 / norm(v)) * v; }
V widen(Vec3<double> v) { return {v.x, v.y, v.z}; }

LD angle_between(V u, V v) { return std::atan2(norm(cross(u, v)), dot(u, v)); }

// Two unit vectors completing n to an orthonormal basis.
std::array<V, 2> tangent_basis(V n) {
  const V helper = std::fabs(n.x) < 0.57L ? V{1, 0, 0} : (std::fabs(n.y) < 0.57L ? V{0, 1, 0} : V{0, 0, 1});
  const V e1 = unit(cross(n, helper));
  return {e1, cross(n, e1)};
}

// v·∇²h(u)·w for body X at unit u: (Σ s_k² (axis_k·v)(axis_k·w) − (s(u)·v)(s(u)·w)) / h(u).
LD hessian_form(const Body& x, V u, V v, V w) {
  const LD h = x.support_value(u);
  const V s = x.support_offset(u);
  LD m = 0;
  for (int k = 0; k < 3; ++k) m += x.semi[k] * x.semi[k] * dot(x.axis[k], v) * dot(x.axis[k], w);
  return (m - dot(s, v) * dot(s, w)) / h;
}

// ∇f(n) = −s_A(−n) + s_B(n) − (a − b).
V gradient(const Body& a, const Body& b, V n) {
  return b.support_offset(n) - a.support_offset(-n) - (a.centre - b.centre);
}

// Newton on the sphere from n (see the file comment); returns the local minimum reached.
Minimum descend(const Body& a, const Body& b, V n) {
  LD f = contact_function(a, b, n);
  const LD scale = a.bounding() + b.bounding();
  for (int it = 0; it < 100; ++it) {
    const auto [e1, e2] = tangent_basis(n);
    const V g = gradient(a, b, n);
    const LD g1 = dot(g, e1), g2 = dot(g, e2);
    if (std::hypot(g1, g2) <= 1e-17L * scale) break;
    LD h11 = hessian_form(a, -n, e1, e1) + hessian_form(b, n, e1, e1) - f;
    LD h22 = hessian_form(a, -n, e2, e2) + hessian_form(b, n, e2, e2) - f;
    const LD h12 = hessian_form(a, -n, e1, e2) + hessian_form(b, n, e1, e2);
    const LD lmin = 0.5L * (h11 + h22) - std::sqrt(0.25L * (h11 - h22) * (h11 - h22) + h12 * h12);
    const LD floor = 1e-3L * scale;  // a saddle or a flat direction: a damped gradient step
    if (lmin < floor) h11 += floor - lmin, h22 += floor - lmin;
    const LD det = h11 * h22 - h12 * h12;
    LD t1 = -(h22 * g1 - h12 * g2) / det, t2 = -(h11 * g2 - h12 * g1) / det;
    const LD len = std::hypot(t1, t2);
    if (len > 0.5L) t1 *= 0.5L / len, t2 *= 0.5L / len;
    bool moved = false;
    for (int k = 0; k < 50 && !moved; ++k, t1 *= 0.5L, t2 *= 0.5L) {
      const V m = unit(n + t1 * e1 + t2 * e2);
      const LD fm = contact_function(a, b, m);
      if (fm < f) n = m, f = fm, moved = true;
    }
    if (!moved) break;
  }
  return {n, f};
}

// n_samples directions spread evenly over the sphere (Fibonacci lattice).
void fibonacci(std::vector<V>& out, int n_samples) {
  const LD golden = kPi * (3 - std::sqrt(5.0L));
  for (int i = 0; i < n_samples; ++i) {
    const LD z = 1 - (2 * LD(i) + 1) / LD(n_samples), r = std::sqrt(1 - z * z);
    out.push_back({r * std::cos(golden * LD(i)), r * std::sin(golden * LD(i)), z});
  }
}

// Rings of directions at the given angles around unit n.
void cap(std::vector<V>& out, V n) {
  const auto [e1, e2] = tangent_basis(n);
  out.push_back(n);
  for (const LD deg : {0.5L, 2.0L, 8.0L})
    for (int k = 0; k < 8; ++k) {
      const LD t = deg * kPi / 180, phi = 2 * kPi * LD(k) / 8;
      out.push_back(std::cos(t) * n + std::sin(t) * (std::cos(phi) * e1 + std::sin(phi) * e2));
    }
}

std::string vec_text(V v) {
  return fmt::format("({:.6g}, {:.6g}, {:.6g})", double(v.x), double(v.y), double(v.z));
}

}  // namespace

LD Body::bounding() const { return std::max({semi[0], semi[1], semi[2]}); }

LD Body::curvature_radius() const {
  const LD lo = std::min({semi[0], semi[1], semi[2]});
  return lo * lo / bounding();
}

LD Body::support_value(V u) const {
  LD s = 0;
  for (int k = 0; k < 3; ++k) {
    const LD c = semi[k] * dot(axis[k], u);
    s += c * c;
  }
  return std::sqrt(s);
}

V Body::support_offset(V u) const {
  const LD h = support_value(u);
  V p{0, 0, 0};
  for (int k = 0; k < 3; ++k) p = p + (semi[k] * semi[k] * dot(axis[k], u) / h) * axis[k];
  return p;
}

Body sphere(Vec3<double> centre, double radius) {
  const LD r = radius;
  return {widen(centre), {r, r, r}, {V{1, 0, 0}, V{0, 1, 0}, V{0, 0, 1}}};
}

Body ellipsoid(Vec3<double> centre, Vec3<double> semi_axes, std::array<double, 4> q) {
  const LD len = std::sqrt(LD(q[0]) * q[0] + LD(q[1]) * q[1] + LD(q[2]) * q[2] + LD(q[3]) * q[3]);
  const LD w = q[0] / len, x = q[1] / len, y = q[2] / len, z = q[3] / len;
  // The columns of the rotation matrix of (w, x, y, z): the images of the local axes.
  const V ex{1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)};
  const V ey{2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)};
  const V ez{2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)};
  return {widen(centre), {semi_axes.x, semi_axes.y, semi_axes.z}, {ex, ey, ez}};
}

LD contact_function(const Body& a, const Body& b, V n) {
  return a.support_value(-n) + b.support_value(n) - dot(n, a.centre - b.centre);
}

Minimum global_minimum(const Body& a, const Body& b, const V* near) {
  std::vector<V> dirs;
  fibonacci(dirs, 512);
  for (const Body* x : {&a, &b})
    for (const V& e : x->axis) dirs.push_back(e), dirs.push_back(-e);
  const V r = a.centre - b.centre;
  if (norm(r) > 0) dirs.push_back(unit(r)), dirs.push_back(-unit(r));
  if (near) cap(dirs, *near);

  std::vector<Minimum> samples;
  for (const V& n : dirs) samples.push_back({n, contact_function(a, b, n)});
  std::sort(samples.begin(), samples.end(), [](const Minimum& x, const Minimum& y) { return x.f < y.f; });
  // Refine the best samples that lie more than 5° from every start taken so far (at most 8 starts).
  std::vector<V> starts;
  Minimum best = samples.front();
  for (const Minimum& s : samples) {
    if (starts.size() == 8) break;
    if (std::any_of(starts.begin(), starts.end(), [&](V t) { return angle_between(t, s.n) < 5 * kPi / 180; }))
      continue;
    starts.push_back(s.n);
    const Minimum m = descend(a, b, s.n);
    if (m.f < best.f) best = m;
  }
  return best;
}

Verdict judge_answer(const Body& a, const Body& b, const Answer& ans, double tol) {
  Verdict v;
  const LD L = std::max(a.bounding(), b.bounding());
  const V pa = widen(ans.position_on_a), pb = widen(ans.position_on_b), n_raw = widen(ans.normal_on_b);
  const LD n_len = norm(n_raw);
  const V n = (1 / n_len) * n_raw;
  const Minimum deepest = global_minimum(a, b, std::isfinite(n_len) && n_len > 0 ? &n : nullptr);
  v.distance = double(-deepest.f);
  auto fail = [&](std::string reason) {
    v.reason = std::move(reason);
    return v;
  };
  if (!std::isfinite(n_len) || !(std::fabs(1 - n_len) <= 1e-6L + tol / L))
    return fail(
        fmt::format("normal_on_b {} is not a unit vector (length {:.9g})", vec_text(n_raw), double(n_len)));
  struct Side {
    const char* point;
    const char* body;
    const Body& x;
    V p, outward;
  };
  for (const Side& s : {Side{"position_on_a", "A", a, pa, -n}, Side{"position_on_b", "B", b, pb, n}}) {
    // F(p) = |D⁻¹ Rᵀ (p − x)|² − 1; first-order distance to the surface |F| / |∇F|.
    LD F = -1;
    V grad{0, 0, 0};
    for (int k = 0; k < 3; ++k) {
      const LD l = dot(s.x.axis[k], s.p - s.x.centre), e2 = s.x.semi[k] * s.x.semi[k];
      F += l * l / e2;
      grad = grad + (2 * l / e2) * s.x.axis[k];
    }
    const LD off = std::fabs(F) / norm(grad);
    if (!(off <= tol))
      return fail(fmt::format("{} {} is {:.3g} off {}'s surface (tolerance {:.3g})", s.point, vec_text(s.p),
                              double(off), s.body, tol));
    const LD turn = angle_between(grad, s.outward), allowed = tol / s.x.curvature_radius();
    if (!(turn <= allowed))
      return fail(fmt::format("{}'s surface normal at {} is {:.3g}° from {} (tolerance {:.3g}°)", s.body,
                              s.point, double(turn * 180 / kPi), s.body[0] == 'A' ? "−n" : "n",
                              double(allowed * 180 / kPi)));
  }
  const LD gap = norm(pa - (pb + LD(ans.distance) * n));
  if (!(gap <= tol))
    return fail(
        fmt::format("position_on_a differs from position_on_b + n·distance by {:.3g} (tolerance {:.3g})",
                    double(gap), tol));
  const LD f_n = contact_function(a, b, n);
  if (deepest.f < f_n - tol)
    return fail(
        fmt::format("not the global minimum: direction {} ({:.3g}° from n) gives distance {:.6g}, deeper "
                    "than the answer's "
                    "{:.6g}",
                    vec_text(deepest.n), double(angle_between(deepest.n, n) * 180 / kPi), double(-deepest.f),
                    double(-f_n)));
  v.ok = true;
  return v;
}

}  // namespace cg::judge
