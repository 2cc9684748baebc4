#pragma once
// One step of the granular dynamics as per-item functions over plain arrays, shared by both
// backends (kernels/host/dem_*.cpp loop over them with OpenMP, kernels/cuda/dem_*.cuh call them one
// thread per item), so the CPU backend is the CUDA backend's oracle bit for bit:
//   contact_terms(k)  contact row k: its force, torques and spring (core/dem_contact.hpp)
//   body_terms(i)     body i: the sum of its contacts' terms in a fixed order (the rows where it is A
//                     in row order, then the rows where it is B in the order of the rows sorted by
//                     B, stably), then its walls in wall order, then gravity; the walls' springs
//   kick_drift / kick (core/dem_body.hpp)
// No floating-point atomics anywhere: the order of every sum is fixed, whatever the threads.
#include <cstddef>
#include <cstdint>

#include "core/dem_body.hpp"
#include "core/dem_contact.hpp"
#include "core/dem_walls.hpp"

namespace cg::dem {

// The bodies' arrays (host or DEVICE), index = body (local) id.
struct BodyArrays {
  Vec3<double>* position;
  Vec3<double>* velocity;
  Vec3<double>* omega;
  Vec3<double>* momentum;
  Quat<double>* orientation;
  Vec3<double>* force;
  Vec3<double>* torque;
  const BodyProps* props;
  const Shape* shape;             // null: all spheres
  const Vec3<double>* semi_axes;  // ellipsoids' (rows of spheres unread)
  const double* radius;           // bounding radius (a sphere's radius)
  std::size_t count;

  CG_HD bool ellipsoid(std::size_t i) const { return shape && shape[i] == Shape::ellipsoid; }
  // Body i's state. A sphere's angular momentum and orientation are never read nor changed (its
  // spin is ω; it has no orientation): a sphere's state holds zero and the identity there, and its
  // rows of those arrays are not loaded (the bytes a contact and a step read).
  CG_HD BodyState state(std::size_t i) const {
    BodyState s{position[i], velocity[i], omega[i], {0, 0, 0}, {1, 0, 0, 0}, force[i], torque[i]};
    if (ellipsoid(i)) {
      s.momentum = momentum[i];
      s.orientation = orientation[i];
    }
    return s;
  }
  // What the integration changes: position, velocity and spin (ellipsoids: angular momentum and
  // orientation too). Force and torque are the body stage's (body_terms), never stored here.
  CG_HD void store(std::size_t i, const BodyState& b) const {
    position[i] = b.position;
    velocity[i] = b.velocity;
    omega[i] = b.omega;
    if (ellipsoid(i)) {
      momentum[i] = b.momentum;
      orientation[i] = b.orientation;
    }
  }
};

// The contact rows of the step (the engine's output, local ids; host or DEVICE), Real as detected.
template <class Real>
struct ContactRows {
  const std::int64_t* id_a;
  const std::int64_t* id_b;
  const Vec3<Real>* position_on_a;
  const Vec3<Real>* position_on_b;
  const Vec3<Real>* normal_on_b;
  const Real* distance;
  const std::int64_t* previous_row;
  std::size_t count;
};

// Each contact's terms (row order) and the springs carried between steps: `xi` and `normal` of this
// step (written by contact_terms), `old_xi` and `old_normal` the previous step's (read through
// previous_row).
struct ContactTerms {
  Vec3<double>* force;     // on A (B: −force)
  Vec3<double>* torque_a;  // on A
  Vec3<double>* torque_b;  // on B
  double* energy;
  Vec3<double>* xi;
  Vec3<double>* normal;
  const Vec3<double>* old_xi;
  const Vec3<double>* old_normal;
};

// The step's constants.
struct StepConstants {
  ContactLaw law;
  Vec3<double> gravity;
  const Wall* walls;  // host or DEVICE
  int wall_count;
  double dt;
  bool synchronized;  // false: plain velocity Verlet (damping and the spring's plane at the half step)
};

CG_HD Vec3<double> unit(Vec3<double> v) {
  const double n = cg_sqrt(dot(v, v));
  return n > 0 ? (1.0 / n) * v : v;
}

// Contact row k's terms: what contact_terms stores, and what a body's sum over its rows adds.
struct ContactResult {
  Vec3<double> force, torque_a, torque_b, xi, normal;
  double energy;
};

// Contact row k's point: halfway between its points on A and on B (where its force acts).
template <class Real>
CG_HD Vec3<double> contact_point(std::size_t k, const ContactRows<Real>& rows) {
  const Vec3<double> pa = vec_cast<double>(rows.position_on_a[k]),
                     pb = vec_cast<double>(rows.position_on_b[k]);
  return 0.5 * (pa + pb);
}

// Contact row k's terms from the bodies' states and the last step's springs (read through
// previous_row), nothing written: any caller gets the same bits. old_normal: the last step's normals,
// as ContactTerms keeps them (double) or as they were detected (N = Real: the same values, a
// Real's double being exact).
template <class Real, class N>
CG_HD ContactResult contact_result(std::size_t k, const ContactRows<Real>& rows, const BodyArrays& b,
                                   const StepConstants& c, const Vec3<double>* old_xi,
                                   const Vec3<N>* old_normal) {
  const std::size_t ia = static_cast<std::size_t>(rows.id_a[k]), ib = static_cast<std::size_t>(rows.id_b[k]);
  const Vec3<double> point = contact_point(k, rows);
  const Vec3<double> n = vec_cast<double>(rows.normal_on_b[k]);
  const std::int64_t prev = rows.previous_row[k];
  const BodyState sa = b.state(ia), sb = b.state(ib);
  const BodyProps& qa = b.props[ia];
  const BodyProps& qb = b.props[ib];
  const bool ea = b.ellipsoid(ia), eb = b.ellipsoid(ib);
  const Vec3<double> ra = point - sa.position, rb = point - sb.position;
  // the contact point's relative velocity at the half step (the state's) and at the step
  const Vec3<double> v_half = (sa.velocity + cross(sa.omega, ra)) - (sb.velocity + cross(sb.omega, rb));
  ContactInput in;
  in.normal = n;
  in.overlap = -double(rows.distance[k]);
  in.v_half = v_half;
  in.dt = c.dt;
  if (c.synchronized) {
    const Vec3<double> wa = synced_omega(sa, qa, ea, c.dt), wb = synced_omega(sb, qb, eb, c.dt);
    in.v_sync =
        (synced_velocity(sa, qa, c.dt) + cross(wa, ra)) - (synced_velocity(sb, qb, c.dt) + cross(wb, rb));
    in.w_rel = wa - wb;
    in.half_normal = prev >= 0 ? unit(vec_cast<double>(old_normal[prev]) + n) : n;
  } else {
    in.v_sync = v_half;
    in.w_rel = sa.omega - sb.omega;
    in.half_normal = n;
  }
  const Pair pair = pair_of(qa.radius, qa.mass, qa.fixed, qb.radius, qb.mass, qb.fixed);
  const double ia_mean = (qa.inertia.x + qa.inertia.y + qa.inertia.z) / 3.0;
  const double ib_mean = (qb.inertia.x + qb.inertia.y + qb.inertia.z) / 3.0;
  const Vec3<double> old = prev >= 0 ? old_xi[prev] : Vec3<double>{0, 0, 0};
  const double inertia = qa.fixed ? ib_mean : (qb.fixed ? ia_mean : ia_mean * ib_mean / (ia_mean + ib_mean));
  const ContactOutput o = contact_force(c.law, pair, inertia, in, old);
  return {o.force, cross(ra, o.force) + o.rolling_torque, cross(rb, -o.force) - o.rolling_torque, o.xi, n,
          o.energy};
}

// Contact row k (file comment). Null torque_a and torque_b: the torques are not stored (the body
// stage takes them from the row's point: torques_from_points); null energy: not stored.
template <class Real>
CG_HD void contact_terms(std::size_t k, const ContactRows<Real>& rows, const BodyArrays& b,
                         const StepConstants& c, const ContactTerms& t) {
  const ContactResult r = contact_result(k, rows, b, c, t.old_xi, t.old_normal);
  t.force[k] = r.force;
  if (t.torque_a) t.torque_a[k] = r.torque_a;
  if (t.torque_b) t.torque_b[k] = r.torque_b;
  if (t.energy) t.energy[k] = r.energy;
  t.xi[k] = r.xi;
  t.normal[k] = r.normal;
}

// Where body i's terms lie: rows [a_begin[i], a_begin[i + 1]) (it is A; rows sorted by A), and
// by_b[j] for j in [b_begin[i], b_begin[i + 1]) (it is B; by_b: the rows stably sorted by B).
struct BodyRowIndex {
  const std::uint32_t* a_begin;  // count + 1
  const std::uint32_t* b_begin;  // count + 1
  const std::uint32_t* by_b;     // rows
};

// Each body's wall springs (count × wall_count, body-major) and the energy of its wall contacts.
struct WallTerms {
  Vec3<double>* xi;
  double* energy;  // count
};

// Body i's rows as B in ascending row order: v[0, m) sorted in place (the row numbers are distinct,
// so any correct sort gives the same order): insertion for the few rows a body has, heapsort beyond
// (a large body's many rows, in O(m log m) with no memory of its own). One thread per body on the
// device (cuda/dem_sums.cuh), no host synchronisation.
CG_HD void sift_down(std::uint32_t* v, std::size_t root, std::size_t end) {
  for (;;) {
    std::size_t child = 2 * root + 1;
    if (child >= end) return;
    if (child + 1 < end && v[child] < v[child + 1]) ++child;
    if (!(v[root] < v[child])) return;
    const std::uint32_t t = v[root];
    v[root] = v[child];
    v[child] = t;
    root = child;
  }
}
CG_HD void sort_rows(std::uint32_t* v, std::size_t m) {
  if (m <= 16) {
    for (std::size_t j = 1; j < m; ++j) {
      const std::uint32_t x = v[j];
      std::size_t at = j;
      for (; at > 0 && v[at - 1] > x; --at) v[at] = v[at - 1];
      v[at] = x;
    }
    return;
  }
  for (std::size_t root = m / 2; root-- > 0;) sift_down(v, root, m);
  for (std::size_t end = m; end-- > 1;) {
    const std::uint32_t t = v[0];
    v[0] = v[end];
    v[end] = t;
    sift_down(v, 0, end);
  }
}

// Where the law has no rolling resistance (every rolling torque zero): a contact's torque on a
// body at `position` from the row's point and the force on that body, the same expression as
// contact_result's (its rolling torque being {0, 0, 0}), so the same bits as the torque stored.
template <class Real>
CG_HD Vec3<double> torque_on_a(std::size_t k, const ContactRows<Real>& rows, Vec3<double> position,
                               Vec3<double> force) {
  return cross(contact_point(k, rows) - position, force) + Vec3<double>{0, 0, 0};
}
template <class Real>
CG_HD Vec3<double> torque_on_b(std::size_t k, const ContactRows<Real>& rows, Vec3<double> position,
                               Vec3<double> force) {
  return cross(contact_point(k, rows) - position, -force) - Vec3<double>{0, 0, 0};
}
CG_HD bool torques_from_points(const StepConstants& c) { return !(c.law.rolling_friction > 0); }

// Body i's sums over its rows as A (row order) and as B (by_b order), onto f and tau, with the
// torques from the rows' points (torque_on_a, torque_on_b: no torque stored): the same order and
// the same terms as a_sums then body_terms_after_a's sums, so the same bits.
template <class Real>
CG_HD void contact_sums_from_points(std::size_t i, const BodyArrays& b, const ContactRows<Real>& rows,
                                    const ContactTerms& t, const BodyRowIndex& index, Vec3<double>& f,
                                    Vec3<double>& tau) {
  const Vec3<double> x = b.position[i];
  for (std::uint32_t k = index.a_begin[i]; k < index.a_begin[i + 1]; ++k) {
    const Vec3<double> fk = t.force[k];
    f = f + fk;
    tau = tau + torque_on_a(k, rows, x, fk);
  }
  for (std::uint32_t j = index.b_begin[i]; j < index.b_begin[i + 1]; ++j) {
    const std::uint32_t k = index.by_b[j];
    const Vec3<double> fk = t.force[k];
    f = f - fk;
    tau = tau + torque_on_b(k, rows, x, fk);
  }
}

// Body i's sums over its rows as A, in row order, onto f and tau.
CG_HD void a_sums(std::size_t i, const ContactTerms& t, const BodyRowIndex& index, Vec3<double>& f,
                  Vec3<double>& tau) {
  for (std::uint32_t k = index.a_begin[i]; k < index.a_begin[i + 1]; ++k) {
    f = f + t.force[k];
    tau = tau + t.torque_a[k];
  }
}

// Body i's force and torque into force_out[i], torque_out[i], from f and tau, the sums of its contact
// rows (as A, then as B): its walls, gravity (file comment). b.force, b.torque: the last step's (the
// walls' synchronised velocities read them); the slots path (core/dem_slots.hpp) writes elsewhere.
CG_HD void body_terms_after_contacts(std::size_t i, const BodyArrays& b, const StepConstants& c,
                                     const WallTerms& w, Vec3<double> f, Vec3<double> tau,
                                     Vec3<double>* force_out, Vec3<double>* torque_out) {
  const BodyState s = b.state(i);
  const BodyProps& p = b.props[i];
  const bool ell = b.ellipsoid(i);
  double energy = 0;
  if (c.wall_count > 0) {
    const Quat<double> q = ell ? s.orientation : Quat<double>{1, 0, 0, 0};
    const Vec3<double> axes = ell ? b.semi_axes[i] : Vec3<double>{0, 0, 0};
    const BodyShape shape =
        body_shape(ell ? Shape::ellipsoid : Shape::sphere, s.position, b.radius[i], axes, q);
    const Vec3<double> w_sync = c.synchronized ? synced_omega(s, p, ell, c.dt) : s.omega;
    const Vec3<double> v_sync = c.synchronized ? synced_velocity(s, p, c.dt) : s.velocity;
    for (int k = 0; k < c.wall_count; ++k) {
      Vec3<double>& xi = w.xi[i * std::size_t(c.wall_count) + std::size_t(k)];
      const WallContact wc = wall_contact(c.walls[k], shape);
      if (!(wc.overlap > 0)) {
        xi = {0, 0, 0};
        continue;
      }
      const Vec3<double> r = wc.point - s.position;
      ContactInput in;
      in.normal = wc.normal;
      in.half_normal = wc.normal;
      in.overlap = wc.overlap;
      in.v_half = s.velocity + cross(s.omega, r);
      in.v_sync = v_sync + cross(w_sync, r);
      in.w_rel = w_sync;
      in.dt = c.dt;
      const Pair pair{p.radius, p.mass};
      const double inertia = (p.inertia.x + p.inertia.y + p.inertia.z) / 3.0;
      const ContactOutput o = contact_force(c.law, pair, inertia, in, xi);
      xi = o.xi;
      f = f + o.force;
      tau = tau + cross(r, o.force) + o.rolling_torque;
      energy = energy + o.energy;
    }
  }
  f = f + p.mass * c.gravity;
  force_out[i] = f;
  torque_out[i] = tau;
  w.energy[i] = energy;
}
// The same into b.force[i], b.torque[i] (the rows path: every contact's terms are computed before).
CG_HD void body_terms_after_contacts(std::size_t i, const BodyArrays& b, const StepConstants& c,
                                     const WallTerms& w, Vec3<double> f, Vec3<double> tau) {
  body_terms_after_contacts(i, b, c, w, f, tau, b.force, b.torque);
}

// Body i's force and torque of the step into b.force[i], b.torque[i], from f and tau, the sums of its
// rows as A (from zero, in row order): its rows as B, its walls, gravity (file comment).
CG_HD void body_terms_after_a(std::size_t i, const BodyArrays& b, const StepConstants& c,
                              const ContactTerms& t, const BodyRowIndex& index, const WallTerms& w,
                              Vec3<double> f, Vec3<double> tau) {
  for (std::uint32_t j = index.b_begin[i]; j < index.b_begin[i + 1]; ++j) {
    const std::uint32_t k = index.by_b[j];
    f = f - t.force[k];
    tau = tau + t.torque_b[k];
  }
  body_terms_after_contacts(i, b, c, w, f, tau);
}

// Body i's force and torque of the step into b.force[i], b.torque[i] (file comment).
CG_HD void body_terms(std::size_t i, const BodyArrays& b, const StepConstants& c, const ContactTerms& t,
                      const BodyRowIndex& index, const WallTerms& w) {
  Vec3<double> f{0, 0, 0}, tau{0, 0, 0};
  a_sums(i, t, index, f, tau);
  body_terms_after_a(i, b, c, t, index, w, f, tau);
}

// The passes of a step whose halo overlaps its forces (kernels/dem.hpp: finish_step_sending): the
// edge rows (edge[i] != 0: the rows the halo sends or receives) and every contact touching one
// first, the interior (the other rows and contacts) after. Each contact and body is computed once,
// by the same function, whatever the pass: the bits of one pass over all.
enum class Pass : int { all, edge, interior };
CG_HD bool body_in_pass(std::size_t i, const std::uint8_t* edge, Pass pass) {
  return pass == Pass::all || (edge[i] != 0) == (pass == Pass::edge);
}
template <class Real>
CG_HD bool contact_in_pass(std::size_t k, const ContactRows<Real>& rows, const std::uint8_t* edge,
                           Pass pass) {
  if (pass == Pass::all) return true;
  const bool touches = edge[rows.id_a[k]] != 0 || edge[rows.id_b[k]] != 0;
  return touches == (pass == Pass::edge);
}

// Body i's energies: kinetic, and potential of gravity (−m g·x; the walls' elastic energy is in
// WallTerms::energy, the contacts' in ContactTerms::energy).
struct BodyEnergy {
  double kinetic, gravity;
};
CG_HD BodyEnergy body_energy(std::size_t i, const BodyArrays& b, Vec3<double> gravity) {
  const BodyState s = b.state(i);
  const BodyProps& p = b.props[i];
  return {kinetic_energy(s, p, b.ellipsoid(i)), -p.mass * dot(gravity, s.position)};
}

}  // namespace cg::dem
