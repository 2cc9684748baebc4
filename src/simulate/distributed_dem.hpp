#pragma once
// contactgrid simulate under mpirun with the forces on the host (CONTACTGRID_SIMULATE_RANKS=host; the
// default keeps each rank's bodies on its backend: resident_dem.hpp): DistributedDem, one rank's
// bodies and ghosts, their contacts by the engine and their forces by the host's shared core math,
// the records the ranks exchange (ghosts' state, the terms of pairs across a cut, the springs and the
// per-body state that move with a body). distributed.cpp sequences a run over it.
#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <numeric>
#include <optional>
#include <type_traits>

#include "agreed_stage.hpp"
#include "collectives.hpp"
#include "core/dem_step.hpp"
#include "core/dem_sum.hpp"
#include "history.hpp"
#include "resident_steps.hpp"
#include "routing.hpp"
#include "session.hpp"
#include "simulate/rank_records.hpp"
#include "simulate/simulate.hpp"

namespace cg::sim {

// A halo row's state, as the ghost's holder needs it for contact_terms.
struct GhostRecord {
  std::int64_t id;
  Vec3<double> position, velocity, omega, momentum, force, torque, semi_axes;
  Quat<double> orientation;
  double radius;
  Shape shape;
};

// The terms of a pair whose B is another rank's body, to that rank.
struct TermRecord {
  std::int64_t a, b;
  Vec3<double> force, torque_b;
};

// A tangential spring carried between steps (the history of one pair).
struct HistoryRow {
  PairKey key;
  std::int64_t age;
  Vec3<double> xi, normal;
};

// The per-body state that migrates with a body (StepBodies::state), walls' springs after it.
struct MotionRecord {
  Vec3<double> velocity, omega, momentum, force, torque;
};

template <class Real>
class DistributedDem {
 public:
  DistributedDem(const Session& session, const DemBodies& all, const DemOptions& options, int threads)
      : m_session(session),
        m_options(options),
        m_threads(threads),
        m_walls(static_cast<int>(options.walls.size())),
        m_shapes(all.has_ellipsoids()),
        m_engine(engine_options(options.engine)) {
    m_alpha = damping_for_restitution(options.material.restitution);
    const dem::Material& m = options.material;
    m_c.law = {m.young / (2 * (1 - m.poisson * m.poisson)), m.young / (4 * (2 - m.poisson) * (1 + m.poisson)),
               m_alpha, m.friction, m.rolling_friction};
    m_c.gravity = options.gravity;
    m_c.walls = m_options.walls.data();
    m_c.wall_count = m_walls;
    m_c.dt = options.dt;
    m_c.synchronized = options.synchronized;
    // the slabs: along the centres' longest extent, cut at their quantiles (every rank: the same)
    const std::size_t n = all.size();
    Vec3<double> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    for (const Vec3<double>& p : all.position) {
      lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
      hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
    const Vec3<double> e = hi - lo;
    const int axis = e.x >= e.y && e.x >= e.z ? 0 : (e.y >= e.z ? 1 : 2);
    std::vector<double> sample(n);
    for (std::size_t i = 0; i < n; ++i) sample[i] = component(all.position[i], axis);
    const SlabDecomposition slabs = SlabDecomposition::from_sample(axis, sample, session.size());
    m_loop.emplace(const_cast<Session&>(session), m_engine, slabs, StepMotion{}, threads);
    // this rank's bodies (ascending id) with their motion
    std::vector<std::size_t> mine;
    for (std::size_t i = 0; i < n; ++i)
      if (slabs.owner(sample[i]) == session.rank()) mine.push_back(i);
    StepBodies b = sized_step_bodies(mine.size(), m_shapes, state_bytes());
    resize_owned(mine.size());
    for (std::size_t k = 0; k < mine.size(); ++k) {
      const std::size_t i = mine[k];
      b.position[k] = all.position[i];
      b.radius[k] = all.radius[i];
      b.id[k] = static_cast<std::int64_t>(i);
      if (m_shapes) {
        b.shapes.shape[k] = all.shape[i];
        b.shapes.semi_axes[k] = all.semi_axes[i];
        b.shapes.orientation[k] = all.orientation[i];
      }
      m_velocity[k] = all.velocity.empty() ? Vec3<double>{0, 0, 0} : all.velocity[i];
      m_omega[k] = all.angular_velocity.empty() ? Vec3<double>{0, 0, 0} : all.angular_velocity[i];
    }
    m_loop->bodies() = std::move(b);
    owned_props();
    for (std::size_t k = 0; k < mine.size(); ++k) {  // L = R I Rᵀ ω (as Simulation)
      const dem::BodyProps& p = m_props[k];
      if (m_shapes && m_loop->bodies().shapes.shape[k] == Shape::ellipsoid) {
        const Mat3<double> r = rotation_matrix(m_loop->bodies().shapes.orientation[k]);
        const Vec3<double> l = mul_transpose(r, m_omega[k]);
        m_momentum[k] = mul(r, Vec3<double>{p.inertia.x * l.x, p.inertia.y * l.y, p.inertia.z * l.z});
      } else {
        m_momentum[k] = p.inertia.x * m_omega[k];
      }
    }
    m_loop->update_frame(0);
    m_loop->lay_out();
    detect();
    forces();  // the forces of the start: the first half kick's
  }

  void step(bool /*another: the resident ranks' overlap*/ = false) {
    const double dt = m_options.dt;
    ++m_steps;
    const int step = static_cast<int>(std::min<std::uint64_t>(m_steps, 0x7fffffff));
    agreed_stage(m_session, "simulate", [&] {
      for_owned([dt](dem::BodyState& st, const dem::BodyProps& p, bool e) { dem::kick_drift(st, p, e, dt); });
    });
    m_loop->update_frame(step);
    if (m_loop->rebuild_due()) {
      const auto t = std::chrono::steady_clock::now();
      m_loop->rebalance();
      migrate();
      m_loop->lay_out();
      ++m_rebuilds;
      m_relayout_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
    }
    // every step, after any layout: the moved rows into engine A (nothing when the layout set them)
    m_loop->commit(Moved{true, m_shapes});
    detect();
    forces();
    agreed_stage(m_session, "simulate", [&] {
      for_owned([dt](dem::BodyState& st, const dem::BodyProps& p, bool e) { dem::kick(st, p, e, dt); });
    });
  }

  std::uint64_t steps() const { return m_steps; }
  std::uint64_t rebuilds() const { return m_rebuilds; }
  double relayout_seconds() const { return m_relayout_seconds; }  // this rank's, since the start
  double cell_size() const { return m_loop->frame().cell_size; }
  double alpha() const { return m_alpha; }
  Backend backend() const { return m_engine.backend(); }
  double skin() const { return m_engine.options().skin; }
  StepStats loop_stats() { return m_loop->stats(); }  // collective

  // Collective: the contacts of the last step over the ranks.
  std::uint64_t contact_count() const { return m_session.sum(m_contacts.size()); }

  // Collective: a log row's energies (rank 0) and contacts.
  sim::LogSums log_sums() { return {energies(), contact_count()}; }

  // Collective: every body on rank 0 in id order, over `start` (its radii and shape rows).
  DemBodies gather_bodies(const DemBodies& start) {
    std::vector<BodyOut> mine(owned());
    const StepBodies& b = m_loop->bodies();
    for (std::size_t k = 0; k < mine.size(); ++k)
      mine[k] = {b.id[k], b.position[k], m_velocity[k], m_omega[k],
                 m_shapes ? b.shapes.orientation[k] : Quat<double>{1, 0, 0, 0}};
    return sim::bodies_on_root(m_session, mine, start);
  }

  // Collective: the energies on rank 0, summed in the one-rank order (ids; contacts by pair).
  DemEnergies energies() {
    const dem::BodyArrays b = owned_arrays();
    std::vector<EnergyOut> mine(owned());
    for (std::size_t k = 0; k < mine.size(); ++k) {
      const dem::BodyEnergy e = dem::body_energy(k, b, m_options.gravity);
      mine[k] = {m_loop->bodies().id[k], e.kinetic, e.gravity, m_walls > 0 ? m_wall_energy[k] : 0.0};
    }
    return sim::energies_on_root(m_session, mine, contact_rows(), m_walls > 0);
  }

  // Collective: the last step's contacts on rank 0, sorted, with age (sim::contacts_on_root).
  Contacts<Real> gather_contacts(const std::vector<PairKey>& previous) {
    return sim::contacts_on_root(m_session, contact_rows(), previous);
  }

  // Collective: the keys of the last step's contacts on rank 0, sorted (gather_contacts' `previous`).
  std::vector<PairKey> gather_keys() {
    return sim::keys_on_root(m_session, std::vector<PairKey>(m_history.keys.begin(), m_history.keys.end()));
  }

 private:
  static EngineOptions engine_options(EngineOptions e) {
    e.history = false;  // the contacts' history is this rank's (step_history over A's and B's rows)
    e.fields = Fields::basic;
    return e;
  }
  std::size_t state_bytes() const {
    return sizeof(MotionRecord) + std::size_t(m_walls) * sizeof(Vec3<double>);
  }
  std::size_t owned() { return m_loop->bodies().size(); }

  void resize_owned(std::size_t n) {
    for (auto* v : {&m_velocity, &m_omega, &m_momentum, &m_force, &m_torque}) v->assign(n, {0, 0, 0});
    m_wall_xi.assign(n * std::size_t(m_walls), {0, 0, 0});
    m_wall_energy.assign(n, 0);
    m_identity.assign(n, Quat<double>{1, 0, 0, 0});
  }

  void owned_props() {
    const StepBodies& b = m_loop->bodies();
    m_props.resize(b.size());
    for (std::size_t k = 0; k < b.size(); ++k) {
      const Shape s = m_shapes ? b.shapes.shape[k] : Shape::sphere;
      m_props[k] = dem::body_props(s, b.radius[k], m_shapes ? b.shapes.semi_axes[k] : Vec3<double>{0, 0, 0},
                                   m_options.material.density);
    }
  }

  dem::BodyArrays owned_arrays() {
    StepBodies& b = m_loop->bodies();
    return {b.position.data(),
            m_velocity.data(),
            m_omega.data(),
            m_momentum.data(),
            m_shapes ? b.shapes.orientation.data() : m_identity.data(),
            m_force.data(),
            m_torque.data(),
            m_props.data(),
            m_shapes ? b.shapes.shape.data() : nullptr,
            m_shapes ? b.shapes.semi_axes.data() : nullptr,
            b.radius.data(),
            b.size()};
  }

  template <class F>
  void for_owned(F&& f) {
    const dem::BodyArrays b = owned_arrays();
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(b.count);
#pragma omp parallel for num_threads(m_threads) schedule(static) if (n > 4096)
    for (std::ptrdiff_t i = 0; i < n; ++i) {
      dem::BodyState st = b.state(std::size_t(i));
      f(st, b.props[i], b.ellipsoid(std::size_t(i)));
      b.store(std::size_t(i), st);
    }
  }

  void detect() {
    m_loop->detect_interior();
    m_loop->refresh_ghosts();
    m_loop->detect_boundary();
    m_loop->collect();
    agreed_stage(m_session, "simulate", [&] { m_contacts = m_loop->contacts(); });
  }

  // The history rows of the bodies that leave to their new owners, then the bodies with their state.
  void migrate() {
    const int me = m_session.rank();
    const std::size_t p = static_cast<std::size_t>(m_session.size());
    StepBodies& b = m_loop->bodies();
    std::vector<std::uint64_t> counts(p, 0);
    std::vector<HistoryRow> send, keep;
    agreed_stage(m_session, "simulate", [&] {
      // the owners after the rebalance (StepLoop::migrate's plan)
      std::vector<double> x(b.size());
      for (std::size_t k = 0; k < b.size(); ++k) x[k] = component(b.position[k], m_loop->slabs().axis());
      const ExportPlan plan = make_owner_plan(m_loop->slabs(), x, m_threads);
      std::vector<int> dest(b.size(), me);
      for (std::size_t r = 0; r < p; ++r)
        for (std::size_t k : plan.to(static_cast<int>(r))) dest[k] = static_cast<int>(r);
      std::vector<std::vector<HistoryRow>> to(p);
      for (std::size_t j = 0; j < m_history.size(); ++j) {
        const PairKey key = m_history.keys[j];
        const auto at = std::lower_bound(b.id.begin(), b.id.end(), key.a);
        if (at == b.id.end() || *at != key.a)
          throw Error("simulate: a contact's first body is not this rank's: internal error");
        const HistoryRow row{key, m_history.age[j], m_old_xi[j], m_old_normal[j]};
        const int d = dest[static_cast<std::size_t>(at - b.id.begin())];
        (d == me ? keep : to[static_cast<std::size_t>(d)]).push_back(row);
      }
      for (std::size_t r = 0; r < p; ++r) {
        counts[r] = to[r].size();
        send.insert(send.end(), to[r].begin(), to[r].end());
      }
      // the bodies' state into their bytes
      const std::size_t stride = state_bytes();
      b.state_bytes = stride;
      b.state.resize(b.size() * stride);
      for (std::size_t k = 0; k < b.size(); ++k) {
        const MotionRecord r{m_velocity[k], m_omega[k], m_momentum[k], m_force[k], m_torque[k]};
        std::byte* at = b.state.data() + k * stride;
        std::memcpy(at, &r, sizeof r);
        if (m_walls > 0)
          std::memcpy(at + sizeof r, m_wall_xi.data() + k * std::size_t(m_walls),
                      std::size_t(m_walls) * sizeof(Vec3<double>));
      }
    });
    std::vector<HistoryRow> got = exchange_records(m_session, send, counts);
    m_loop->migrate();
    agreed_stage(m_session, "simulate", [&] {
      keep.insert(keep.end(), got.begin(), got.end());
      std::sort(keep.begin(), keep.end(),
                [](const HistoryRow& x, const HistoryRow& y) { return x.key < y.key; });
      m_history.keys.resize(keep.size());
      m_history.age.resize(keep.size());
      m_old_xi.resize(keep.size());
      m_old_normal.resize(keep.size());
      for (std::size_t j = 0; j < keep.size(); ++j) {
        m_history.keys[j] = keep[j].key;
        m_history.age[j] = keep[j].age;
        m_old_xi[j] = keep[j].xi;
        m_old_normal[j] = keep[j].normal;
      }
      StepBodies& nb = m_loop->bodies();
      const std::size_t stride = state_bytes();
      resize_owned(nb.size());
      for (std::size_t k = 0; k < nb.size(); ++k) {
        MotionRecord r;
        const std::byte* at = nb.state.data() + k * stride;
        std::memcpy(&r, at, sizeof r);
        m_velocity[k] = r.velocity;
        m_omega[k] = r.omega;
        m_momentum[k] = r.momentum;
        m_force[k] = r.force;
        m_torque[k] = r.torque;
        if (m_walls > 0)
          std::memcpy(m_wall_xi.data() + k * std::size_t(m_walls), at + sizeof r,
                      std::size_t(m_walls) * sizeof(Vec3<double>));
      }
      owned_props();
    });
  }

  // The ghosts' state (the halo of the last layout) and the held arrays: owned rows, then the
  // ghosts in ascending id.
  void hold_ghosts() {
    const StepBodies& b = m_loop->bodies();
    const ExportPlan& halo = m_loop->halo();
    const std::size_t p = static_cast<std::size_t>(m_session.size());
    std::vector<std::uint64_t> counts(p, 0);
    std::vector<GhostRecord> send;
    if (halo.offsets.size() == p + 1) {
      counts = halo.counts();
      send.resize(halo.rows.size());
      for (std::size_t w = 0; w < halo.rows.size(); ++w) {
        const std::size_t k = halo.rows[w];
        send[w] = GhostRecord{b.id[k],
                              b.position[k],
                              m_velocity[k],
                              m_omega[k],
                              m_momentum[k],
                              m_force[k],
                              m_torque[k],
                              m_shapes ? b.shapes.semi_axes[k] : Vec3<double>{0, 0, 0},
                              m_shapes ? b.shapes.orientation[k] : Quat<double>{1, 0, 0, 0},
                              b.radius[k],
                              m_shapes ? b.shapes.shape[k] : Shape::sphere};
      }
    }
    std::vector<std::uint64_t> from;
    const std::vector<GhostRecord> got = exchange_records(m_session, send, counts, &from);
    agreed_stage(m_session, "simulate", [&] {
      std::vector<int> source(got.size());
      std::size_t g = 0;
      for (std::size_t r = 0; r < from.size(); ++r)
        for (std::uint64_t j = 0; j < from[r]; ++j) source[g++] = static_cast<int>(r);
      std::vector<std::size_t> order(got.size());
      std::iota(order.begin(), order.end(), std::size_t(0));
      std::sort(order.begin(), order.end(),
                [&](std::size_t x, std::size_t y) { return got[x].id < got[y].id; });
      const std::size_t n = b.size(), h = n + got.size();
      m_ghost_id.resize(got.size());
      m_ghost_rank.resize(got.size());
      m_h_position.assign(b.position.begin(), b.position.end());
      m_h_velocity = m_velocity;
      m_h_omega = m_omega;
      m_h_momentum = m_momentum;
      m_h_force = m_force;
      m_h_torque = m_torque;
      m_h_props = m_props;
      m_h_radius.assign(b.radius.begin(), b.radius.end());
      if (m_shapes) {
        m_h_orientation.assign(b.shapes.orientation.begin(), b.shapes.orientation.end());
        m_h_shape.assign(b.shapes.shape.begin(), b.shapes.shape.end());
        m_h_semi.assign(b.shapes.semi_axes.begin(), b.shapes.semi_axes.end());
      } else {
        m_h_orientation.assign(n, Quat<double>{1, 0, 0, 0});
        m_h_shape.clear();
        m_h_semi.assign(n, {0, 0, 0});
      }
      for (auto* v :
           {&m_h_position, &m_h_velocity, &m_h_omega, &m_h_momentum, &m_h_force, &m_h_torque, &m_h_semi})
        v->resize(h);
      m_h_props.resize(h);
      m_h_radius.resize(h);
      m_h_orientation.resize(h);
      if (m_shapes) m_h_shape.resize(h);
      for (std::size_t j = 0; j < order.size(); ++j) {
        const GhostRecord& r = got[order[j]];
        const std::size_t i = n + j;
        m_ghost_id[j] = r.id;
        m_ghost_rank[j] = source[order[j]];
        m_h_position[i] = r.position;
        m_h_velocity[i] = r.velocity;
        m_h_omega[i] = r.omega;
        m_h_momentum[i] = r.momentum;
        m_h_force[i] = r.force;
        m_h_torque[i] = r.torque;
        m_h_semi[i] = r.semi_axes;
        m_h_orientation[i] = r.orientation;
        m_h_radius[i] = r.radius;
        if (m_shapes) m_h_shape[i] = r.shape;
        m_h_props[i] = dem::body_props(r.shape, r.radius, r.semi_axes, m_options.material.density);
      }
    });
  }

  // The held row of body `id` (owned first, then ghosts).
  std::int64_t held(std::int64_t id) {
    const StepBodies& b = m_loop->bodies();
    const auto at = std::lower_bound(b.id.begin(), b.id.end(), id);
    if (at != b.id.end() && *at == id) return at - b.id.begin();
    const auto g = std::lower_bound(m_ghost_id.begin(), m_ghost_id.end(), id);
    if (g == m_ghost_id.end() || *g != id)
      throw Error("simulate: body " + std::to_string(id) + " of a contact is not held: internal error");
    return static_cast<std::int64_t>(b.size()) + (g - m_ghost_id.begin());
  }

  void forces() {
    hold_ghosts();
    const std::size_t p = static_cast<std::size_t>(m_session.size());
    const std::size_t n = owned();
    std::vector<std::uint64_t> counts(p, 0);
    std::vector<TermRecord> send;
    agreed_stage(m_session, "simulate", [&] {
      Contacts<Real>& c = m_contacts;
      step_history(c, m_history, {}, m_threads);  // previous_row: into m_old_xi, m_old_normal
      const std::size_t k = c.size();
      m_la.resize(k);
      m_lb.resize(k);
      for (std::size_t r = 0; r < k; ++r) {
        m_la[r] = held(c.id_a[r]);
        m_lb[r] = held(c.id_b[r]);
        if (m_la[r] >= static_cast<std::int64_t>(n))
          throw Error("simulate: a contact's first body is not this rank's: internal error");
      }
      const dem::ContactRows<Real> rows{
          m_la.data(),          m_lb.data(),       c.position_on_a.data(), c.position_on_b.data(),
          c.normal_on_b.data(), c.distance.data(), c.previous_row.data(),  k};
      for (auto* v : {&m_t_force, &m_t_torque_a, &m_t_torque_b, &m_xi, &m_normal}) v->resize(k);
      m_t_energy.resize(k);
      const dem::BodyArrays hb{
          m_h_position.data(), m_h_velocity.data(),    m_h_omega.data(),
          m_h_momentum.data(), m_h_orientation.data(), m_h_force.data(),
          m_h_torque.data(),   m_h_props.data(),       m_shapes ? m_h_shape.data() : nullptr,
          m_h_semi.data(),     m_h_radius.data(),      m_h_position.size()};
      const dem::ContactTerms t{m_t_force.data(),  m_t_torque_a.data(), m_t_torque_b.data(),
                                m_t_energy.data(), m_xi.data(),         m_normal.data(),
                                m_old_xi.data(),   m_old_normal.data()};
      const std::ptrdiff_t kk = static_cast<std::ptrdiff_t>(k);
#pragma omp parallel for num_threads(m_threads) schedule(static) if (kk > 4096)
      for (std::ptrdiff_t r = 0; r < kk; ++r) dem::contact_terms(std::size_t(r), rows, hb, m_c, t);
      // the terms of pairs whose B is a ghost, to B's owner, in row order
      std::vector<std::vector<TermRecord>> to(p);
      for (std::size_t r = 0; r < k; ++r)
        if (m_lb[r] >= static_cast<std::int64_t>(n)) {
          const std::size_t g = static_cast<std::size_t>(m_lb[r]) - n;
          to[static_cast<std::size_t>(m_ghost_rank[g])].push_back(
              TermRecord{c.id_a[r], c.id_b[r], m_t_force[r], m_t_torque_b[r]});
        }
      for (std::size_t d = 0; d < p; ++d) {
        counts[d] = to[d].size();
        send.insert(send.end(), to[d].begin(), to[d].end());
      }
    });
    const std::vector<TermRecord> got = exchange_records(m_session, send, counts);
    agreed_stage(m_session, "simulate", [&] {
      const std::size_t k = m_contacts.size();
      // each owned body's rows as B: this rank's and the received, by (B, A)
      struct BEntry {
        std::uint32_t b;
        std::int64_t a;
        std::uint32_t row;
      };
      std::vector<BEntry> entries;
      for (std::size_t r = 0; r < k; ++r)
        if (m_lb[r] < static_cast<std::int64_t>(n))
          entries.push_back({std::uint32_t(m_lb[r]), m_contacts.id_a[r], std::uint32_t(r)});
      m_t_force.resize(k + got.size());
      m_t_torque_b.resize(k + got.size());
      for (std::size_t j = 0; j < got.size(); ++j) {
        const std::int64_t hb = held(got[j].b);
        if (hb >= static_cast<std::int64_t>(n))
          throw Error(
              "simulate: the terms of a contact reached a rank that does not own its body: internal error");
        m_t_force[k + j] = got[j].force;
        m_t_torque_b[k + j] = got[j].torque_b;
        entries.push_back({std::uint32_t(hb), got[j].a, std::uint32_t(k + j)});
      }
      std::sort(entries.begin(), entries.end(),
                [](const BEntry& x, const BEntry& y) { return x.b < y.b || (x.b == y.b && x.a < y.a); });
      m_a_begin.assign(n + 1, 0);
      m_b_begin.assign(n + 1, 0);
      for (std::size_t r = 0; r < k; ++r) ++m_a_begin[static_cast<std::size_t>(m_la[r]) + 1];
      for (const BEntry& e : entries) ++m_b_begin[e.b + 1];
      for (std::size_t i = 0; i < n; ++i) {
        m_a_begin[i + 1] += m_a_begin[i];
        m_b_begin[i + 1] += m_b_begin[i];
      }
      m_by_b.resize(entries.size());
      for (std::size_t j = 0; j < entries.size(); ++j) m_by_b[j] = entries[j].row;
      const dem::BodyArrays b = owned_arrays();
      const dem::ContactTerms t{m_t_force.data(),
                                m_t_torque_a.data(),
                                m_t_torque_b.data(),
                                m_t_energy.data(),
                                nullptr,
                                nullptr,
                                nullptr,
                                nullptr};
      const dem::BodyRowIndex index{m_a_begin.data(), m_b_begin.data(), m_by_b.data()};
      const dem::WallTerms w{m_wall_xi.data(), m_wall_energy.data()};
      const std::ptrdiff_t nn = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for num_threads(m_threads) schedule(static) if (nn > 4096)
      for (std::ptrdiff_t i = 0; i < nn; ++i) dem::body_terms(std::size_t(i), b, m_c, t, index, w);
      std::swap(m_xi, m_old_xi);  // this step's springs are the next step's old ones
      std::swap(m_normal, m_old_normal);
    });
  }

  // This rank's contacts of the last step with their energies.
  std::vector<ContactOut<Real>> contact_rows() const {
    std::vector<ContactOut<Real>> rows(m_contacts.size());
    for (std::size_t k = 0; k < rows.size(); ++k)
      rows[k] = {m_contacts.id_a[k],          m_contacts.id_b[k],
                 m_contacts.age[k],           m_contacts.position_on_a[k],
                 m_contacts.position_on_b[k], m_contacts.normal_on_b[k],
                 m_contacts.distance[k],      m_t_energy[k]};
    return rows;
  }

  const Session& m_session;
  DemOptions m_options;
  int m_threads;
  int m_walls;
  bool m_shapes;
  double m_alpha = 0;
  dem::StepConstants m_c{};
  Engine<Real> m_engine;
  std::optional<StepLoop<Real>> m_loop;
  std::uint64_t m_steps = 0, m_rebuilds = 0;
  double m_relayout_seconds = 0;
  // the owned bodies' motion (row = StepBodies row)
  std::vector<Vec3<double>> m_velocity, m_omega, m_momentum, m_force, m_torque, m_wall_xi;
  std::vector<double> m_wall_energy;
  std::vector<Quat<double>> m_identity;  // sphere-only scenes' orientations
  std::vector<dem::BodyProps> m_props;
  // held rows: owned, then ghosts ascending id
  std::vector<std::int64_t> m_ghost_id;
  std::vector<int> m_ghost_rank;
  std::vector<Vec3<double>> m_h_position, m_h_velocity, m_h_omega, m_h_momentum, m_h_force, m_h_torque,
      m_h_semi;
  std::vector<Quat<double>> m_h_orientation;
  std::vector<double> m_h_radius;
  std::vector<Shape> m_h_shape;
  std::vector<dem::BodyProps> m_h_props;
  // this step's contacts (id_a owned here, global ids), their held rows and terms; the springs
  Contacts<Real> m_contacts;
  std::vector<std::int64_t> m_la, m_lb;
  ContactHistory m_history;
  std::vector<Vec3<double>> m_xi, m_normal, m_old_xi, m_old_normal;
  std::vector<Vec3<double>> m_t_force, m_t_torque_a, m_t_torque_b;
  std::vector<double> m_t_energy;
  std::vector<std::uint32_t> m_a_begin, m_b_begin, m_by_b;
};

}  // namespace cg::sim
