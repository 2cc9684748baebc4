#pragma once
// ResidentDem::relayout (resident_dem.hpp): new slabs from the owned centres where the owned counts
// drifted apart, the owned bodies with their state and their pairs' springs to their new owners, the
// new ghosts, and the rows set again in ascending id (the one-rank order of every sum).
#include "simulate/resident_dem.hpp"

namespace cg {

template <class Real>
void ResidentDem<Real>::relayout() {
  const int me = m_session.rank();
  const std::size_t p = static_cast<std::size_t>(m_session.size());
  ++m_rebuilds;
  if (p == 1) {  // one rank holds every body: nothing to move
    agreed_stage(m_session, "simulate", [&] { m_sim->mark_rows(); });
    return;
  }
  DemState st;
  std::vector<double> sample;
  agreed_stage(m_session, "simulate", [&] {
    st = m_sim->state();
    // a sample of the owned centres along the axis (at most 4096 a rank, every rank's the same way)
    const std::size_t n = m_owned_rows.size(), stride = std::max<std::size_t>(1, n / 4096);
    for (std::size_t j = 0; j < n; j += stride)
      sample.push_back(component(st.rows[m_owned_rows[j]].position, m_axis));
  });
  // new slabs only where the owned counts drifted apart (more than 5 % above the mean on a rank)
  const std::vector<std::uint64_t> counts = allgather_counts(m_session, m_owned_rows.size());
  std::uint64_t total = 0, most = 0;
  for (const std::uint64_t c : counts) {
    total += c;
    most = std::max(most, c);
  }
  const bool rebalance = double(most) > 1.05 * double(total) / double(p) + 16;
  std::vector<double> all_sample;
  if (rebalance)
    all_sample =
        sim::exchange_records(m_session, repeat(sample, p), std::vector<std::uint64_t>(p, sample.size()));
  std::vector<std::uint64_t> body_counts(p, 0), spring_counts(p, 0);
  std::vector<ResidentBodyRecord> bodies;
  std::vector<Vec3<double>> walls;
  std::vector<ResidentSpringRecord> springs;
  agreed_stage(m_session, "simulate", [&] {
    if (rebalance) {
      m_slabs.emplace(SlabDecomposition::from_sample(m_axis, all_sample, static_cast<int>(p)));
      ++m_rebalances;
    }
    auto owner_of = [&](std::size_t k) { return m_slabs->owner(component(st.rows[k].position, m_axis)); };
    std::vector<std::vector<std::size_t>> to(p);
    for (const std::uint32_t k : m_owned_rows) {
      const int d = owner_of(k);
      to[static_cast<std::size_t>(d)].push_back(k);
      if (d != me) ++m_migrated;
    }
    for (std::size_t r = 0; r < p; ++r) {
      body_counts[r] = to[r].size();
      for (const std::size_t k : to[r]) {
        bodies.push_back({m_ids[k], st.rows[k]});
        walls.insert(walls.end(), st.wall_xi.begin() + std::ptrdiff_t(k * m_walls),
                     st.wall_xi.begin() + std::ptrdiff_t((k + 1) * m_walls));
      }
    }
    // each pair whose smaller id this rank owns, to the new owners of its two bodies
    std::vector<std::vector<ResidentSpringRecord>> send(p);
    for (std::size_t j = 0; j < st.history.size(); ++j) {
      const PairKey key = st.history.keys[j];
      const std::size_t a = held_row(key.a);
      if (m_owner[a] != me) continue;
      const ResidentSpringRecord r{key, st.history.age[j], st.xi[j], st.normal[j]};
      const int da = owner_of(a), db = owner_of(held_row(key.b));
      send[static_cast<std::size_t>(da)].push_back(r);
      if (db != da) send[static_cast<std::size_t>(db)].push_back(r);
    }
    for (std::size_t r = 0; r < p; ++r) {
      spring_counts[r] = send[r].size();
      springs.insert(springs.end(), send[r].begin(), send[r].end());
    }
  });
  std::vector<ResidentBodyRecord> owned = sim::exchange_records(m_session, bodies, body_counts);
  std::vector<std::uint64_t> wall_counts(body_counts);
  for (std::uint64_t& c : wall_counts) c *= m_walls;
  const std::vector<Vec3<double>> owned_walls = sim::exchange_records(m_session, walls, wall_counts);
  std::vector<ResidentSpringRecord> got_springs = sim::exchange_records(m_session, springs, spring_counts);
  // the new ghosts: each owned body to the ranks whose slab is within the ghost width
  std::vector<std::uint64_t> ghost_counts(p, 0);
  std::vector<ResidentBodyRecord> ghosts_out;
  std::vector<std::size_t> order;
  agreed_stage(m_session, "simulate", [&] {
    order.resize(owned.size());
    for (std::size_t j = 0; j < order.size(); ++j) order[j] = j;
    std::sort(order.begin(), order.end(),
              [&](std::size_t x, std::size_t y) { return owned[x].id < owned[y].id; });
    std::vector<std::vector<std::size_t>> to(p);
    for (const std::size_t j : order)
      m_slabs->for_each_ghost_rank(component(owned[j].row.position, m_axis), m_width,
                                   [&](int r) { to[static_cast<std::size_t>(r)].push_back(j); });
    for (std::size_t r = 0; r < p; ++r) {
      ghost_counts[r] = to[r].size();
      for (const std::size_t j : to[r]) ghosts_out.push_back(owned[j]);
    }
  });
  std::vector<std::uint64_t> from;
  const std::vector<ResidentBodyRecord> ghosts =
      sim::exchange_records(m_session, ghosts_out, ghost_counts, &from);
  agreed_stage(m_session, "simulate", [&] {
    // the held rows: owned and ghosts merged by id
    struct Held {
      std::int64_t id;
      int owner;
      const ResidentBodyRecord* record;
      const Vec3<double>* walls;  // owned: its wall springs; ghosts: none
    };
    std::vector<Held> held;
    held.reserve(owned.size() + ghosts.size());
    for (const std::size_t j : order)
      held.push_back({owned[j].id, me, &owned[j], m_walls > 0 ? owned_walls.data() + j * m_walls : nullptr});
    std::size_t g = 0;
    for (std::size_t r = 0; r < from.size(); ++r)
      for (std::uint64_t c = 0; c < from[r]; ++c, ++g)
        held.push_back({ghosts[g].id, static_cast<int>(r), &ghosts[g], nullptr});
    std::sort(held.begin(), held.end(), [](const Held& x, const Held& y) { return x.id < y.id; });
    for (std::size_t k = 1; k < held.size(); ++k)
      if (held[k].id == held[k - 1].id)
        throw Error("simulate: body " + std::to_string(held[k].id) + " is held twice: internal error");
    const std::size_t m = held.size();
    m_ids.resize(m);
    m_owner.resize(m);
    for (std::size_t k = 0; k < m; ++k) {
      m_ids[k] = held[k].id;
      m_owner[k] = held[k].owner;
    }
    DemBodies rows = rows_of(m_ids);
    DemState next;
    next.rows.resize(m);
    next.wall_xi.assign(m * m_walls, {0, 0, 0});
    next.wall_energy.assign(m, 0);
    for (std::size_t k = 0; k < m; ++k) {
      const ResidentBodyRecord& r = *held[k].record;
      next.rows[k] = r.row;
      rows.position[k] = r.row.position;
      rows.velocity[k] = r.row.velocity;
      rows.angular_velocity[k] = r.row.omega;
      if (!rows.orientation.empty()) rows.orientation[k] = r.row.orientation;
      if (held[k].walls)
        std::copy(held[k].walls, held[k].walls + m_walls, next.wall_xi.begin() + std::ptrdiff_t(k * m_walls));
    }
    // the springs of the pairs among the held rows, by key
    std::sort(got_springs.begin(), got_springs.end(),
              [](const ResidentSpringRecord& x, const ResidentSpringRecord& y) { return x.key < y.key; });
    auto is_held = [&](std::int64_t id) { return std::binary_search(m_ids.begin(), m_ids.end(), id); };
    for (std::size_t j = 0; j < got_springs.size(); ++j) {
      const ResidentSpringRecord& r = got_springs[j];
      if (j > 0 && !(got_springs[j - 1].key < r.key))
        throw Error("simulate: a pair's spring came twice: internal error");
      if (!is_held(r.key.a) || !is_held(r.key.b)) continue;
      next.history.keys.push_back(r.key);
      next.history.age.push_back(r.age);
      next.xi.push_back(r.xi);
      next.normal.push_back(r.normal);
    }
    next.contact_energy.assign(next.xi.size(), 0);
    m_sim->set_rows(rows, m_ids, next);
    halo_plan(rows.position);
  });
  check_halo_counts();
}

}  // namespace cg
