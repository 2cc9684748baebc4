// The granular dynamics' setup (kernels/dem.hpp): the restitution's damping, the time scales and the
// checks of a setup; the contact law and the bodies' mass properties a simulation starts from
// (dem_setup.hpp).
#include "dem_setup.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>

#include "dem.hpp"

namespace cg {

bool DemBodies::has_ellipsoids() const {
  return std::any_of(shape.begin(), shape.end(), [](Shape s) { return s == Shape::ellipsoid; });
}

// ---- the restitution's damping ---------------------------------------------------------------------

// One dimensionless collision x'' = −max(0, x^{3/2} + α x^{1/4} x'), x(0) = 0, x'(0) = 1 (m* = K =
// v₀ = 1), integrated by classical Runge–Kutta until x returns to 0; the restitution is −x'(end).
// The step (1e-4 of a collision lasting about 3.2) resolves it to about 1e-8.
double restitution_for_damping(double alpha) {
  auto accel = [alpha](double x, double v) {
    if (!(x > 0)) return 0.0;
    const double f = x * std::sqrt(x) + alpha * std::sqrt(std::sqrt(x)) * v;
    return f > 0 ? -f : 0.0;
  };
  const double h = 1e-4;
  double x = 0, v = 1;
  for (int step = 0; step < 10000000; ++step) {
    const double k1x = v, k1v = accel(x, v);
    const double k2x = v + 0.5 * h * k1v, k2v = accel(x + 0.5 * h * k1x, v + 0.5 * h * k1v);
    const double k3x = v + 0.5 * h * k2v, k3v = accel(x + 0.5 * h * k2x, v + 0.5 * h * k2v);
    const double k4x = v + h * k3v, k4v = accel(x + h * k3x, v + h * k3v);
    const double nx = x + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
    const double nv = v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
    if (nx <= 0 && step > 0) {
      // the crossing of x = 0 within the step, linearly: the speed there
      const double s = x / (x - nx);
      return -(v + s * (nv - v));
    }
    x = nx;
    v = nv;
    if (v < 0 && !(accel(x, v) < 0)) return -v;  // no force left: it leaves at this speed
  }
  return 0;
}

double damping_for_restitution(double e) {
  if (!(e > 0 && e <= 1)) throw UsageError("--restitution must be in (0, 1]");
  if (e == 1) return 0;
  double lo = 0, hi = 1;
  while (restitution_for_damping(hi) > e) {
    hi *= 2;
    if (hi > 1e3)
      throw UsageError("--restitution " + std::to_string(e) +
                       " is below what the damping of the force law reaches");
  }
  for (int i = 0; i < 60 && hi - lo > 1e-12 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (restitution_for_damping(mid) > e ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

// ---- time scales and checks ------------------------------------------------------------------------

namespace {
double smallest_radius(const DemBodies& b) {
  double r = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < b.size(); ++i) {
    const bool ell = !b.shape.empty() && b.shape[i] == Shape::ellipsoid;
    r = std::min(r, ell ? std::min({b.semi_axes[i].x, b.semi_axes[i].y, b.semi_axes[i].z}) : b.radius[i]);
  }
  return r;
}

bool finite(Vec3<double> v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }
}  // namespace

dem::ContactLaw law_of(const dem::Material& m, double alpha) {
  return {m.young / (2 * (1 - m.poisson * m.poisson)), m.young / (4 * (2 - m.poisson) * (1 + m.poisson)),
          alpha, m.friction, m.rolling_friction};
}

std::vector<dem::BodyProps> props_of(const DemBodies& b, double density) {
  std::vector<dem::BodyProps> p(b.size());
  for (std::size_t i = 0; i < b.size(); ++i) {
    const Shape s = b.shape.empty() ? Shape::sphere : b.shape[i];
    p[i] = dem::body_props(s, b.radius[i], b.semi_axes.empty() ? Vec3<double>{0, 0, 0} : b.semi_axes[i],
                           density);
    p[i].fixed = !b.fixed.empty() && b.fixed[i] != 0;
  }
  return p;
}

TimeStepLimits time_step_limits(const DemBodies& bodies, const dem::Material& m, double speed) {
  TimeStepLimits t;
  if (bodies.size() == 0) return t;
  const double r = smallest_radius(bodies);
  const double g = m.young / (2 * (1 + m.poisson));
  t.rayleigh = dem::kPi * r * std::sqrt(m.density / g) / (0.1631 * m.poisson + 0.8766);
  const double mass = m.density * 4.0 / 3.0 * dem::kPi * r * r * r;
  const double m_star = mass / 2, r_star = r / 2, e_star = m.young / (2 * (1 - m.poisson * m.poisson));
  t.hertz = speed > 0 ? 2.87 * std::pow(m_star * m_star / (r_star * e_star * e_star * speed), 0.2)
                      : std::numeric_limits<double>::infinity();
  t.automatic = std::min(0.2 * t.rayleigh, t.hertz / 40);
  return t;
}

void check_dem_setup(const DemBodies& b, const DemOptions& o) {
  const dem::Material& m = o.material;
  auto need = [](bool ok, const std::string& what) {
    if (!ok) throw UsageError(what);
  };
  need(m.young > 0 && std::isfinite(m.young), "--young must be a finite number > 0");
  need(m.poisson > -1 && m.poisson < 0.5, "--poisson must be in (-1, 0.5)");
  need(m.density > 0 && std::isfinite(m.density), "--density must be a finite number > 0");
  need(m.restitution > 0 && m.restitution <= 1, "--restitution must be in (0, 1]");
  need(m.friction >= 0 && std::isfinite(m.friction), "--friction must be a finite number >= 0");
  need(m.rolling_friction >= 0 && std::isfinite(m.rolling_friction),
       "--rolling-friction must be a finite number >= 0");
  need(o.dt > 0 && std::isfinite(o.dt), "--dt must be a finite time > 0");
  need(finite(o.gravity), "--gravity must be finite");
  for (std::size_t k = 0; k < o.walls.size(); ++k) {
    const dem::Wall& w = o.walls[k];
    const std::string name = "wall " + std::to_string(k);
    need(finite(w.point), name + ": its point is not finite");
    if (w.kind == dem::WallKind::plane)
      need(finite(w.normal) && std::abs(dot(w.normal, w.normal) - 1) < 1e-12,
           name + ": its normal is not a unit vector");
    if (w.kind == dem::WallKind::cylinder)
      need(w.radius > 0 && std::isfinite(w.radius), name + ": radius must be > 0");
    if (w.kind == dem::WallKind::orifice)
      need(w.hole >= 0 && std::isfinite(w.hole), name + ": hole must be >= 0");
  }
  const std::size_t n = b.size();
  if (b.radius.size() != n || (!b.velocity.empty() && b.velocity.size() != n) ||
      (!b.angular_velocity.empty() && b.angular_velocity.size() != n) ||
      (!b.fixed.empty() && b.fixed.size() != n) ||
      (!b.shape.empty() && (b.shape.size() != n || b.semi_axes.size() != n || b.orientation.size() != n)))
    throw UsageError("simulate: the body arrays differ in length");
  for (std::size_t i = 0; i < n; ++i) {
    if ((!b.velocity.empty() && !finite(b.velocity[i])) ||
        (!b.angular_velocity.empty() && !finite(b.angular_velocity[i])))
      throw InputError("body " + std::to_string(i) + ": its velocity or angular velocity is not finite");
  }
  // a body starting inside a wall (its centre beyond it, or deeper than half its size)
  for (std::size_t i = 0; i < n; ++i) {
    const bool ell = !b.shape.empty() && b.shape[i] == Shape::ellipsoid;
    const dem::BodyShape s = dem::body_shape(ell ? Shape::ellipsoid : Shape::sphere, b.position[i],
                                             b.radius[i], ell ? b.semi_axes[i] : Vec3<double>{0, 0, 0},
                                             ell ? b.orientation[i] : Quat<double>{1, 0, 0, 0});
    const double size = ell ? std::min({b.semi_axes[i].x, b.semi_axes[i].y, b.semi_axes[i].z}) : b.radius[i];
    for (std::size_t k = 0; k < o.walls.size(); ++k) {
      const dem::WallContact c = dem::wall_contact(o.walls[k], s);
      if (c.overlap > 0.5 * size) {
        std::ostringstream msg;
        msg << "body " << i << " starts inside wall " << k << " (overlap " << c.overlap << ", size " << size
            << ")";
        throw InputError(msg.str());
      }
    }
  }
}

}  // namespace cg
