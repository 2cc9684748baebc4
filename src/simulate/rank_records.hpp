#pragma once
// What the ranks of `contactgrid simulate` under mpirun send each other and gather on rank 0, shared
// by both ways a rank computes its bodies (distributed.cpp: the forces on the host; resident_dem.hpp:
// each rank's rows where its backend computes): records between ranks as bytes, and rank 0's frame
// bodies, energies (summed in the one-rank order of core/dem_sum.hpp) and contacts from every
// rank's rows.
#include <algorithm>
#include <cstring>
#include <type_traits>
#include <vector>

#include "collectives.hpp"
#include "core/dem_sum.hpp"
#include "dem.hpp"
#include "session.hpp"

namespace cg::sim {

// Records between ranks, as bytes (collectives.hpp: alltoallv_bytes), grouped by destination rank.
template <class T>
std::vector<T> exchange_records(const Session& session, const std::vector<T>& send,
                                const std::vector<std::uint64_t>& counts,
                                std::vector<std::uint64_t>* received = nullptr) {
  static_assert(std::is_trivially_copyable_v<T>);
  std::vector<std::byte> bytes(send.size() * sizeof(T));
  if (!send.empty()) std::memcpy(bytes.data(), send.data(), bytes.size());
  std::vector<std::uint64_t> sb(counts), rb;
  for (std::uint64_t& c : sb) c *= sizeof(T);
  const std::vector<std::byte> got = alltoallv_bytes(session, bytes, sb, rb);
  std::vector<T> out(got.size() / sizeof(T));
  if (!out.empty()) std::memcpy(out.data(), got.data(), got.size());
  if (received) {
    received->resize(rb.size());
    for (std::size_t r = 0; r < rb.size(); ++r) (*received)[r] = rb[r] / sizeof(T);
  }
  return out;
}

// Every rank's records on rank 0, in rank order (the others: none).
template <class T>
std::vector<T> gather_records(const Session& session, const std::vector<T>& mine) {
  std::vector<std::uint64_t> counts(static_cast<std::size_t>(session.size()), 0);
  counts[0] = mine.size();
  return exchange_records(session, mine, counts);
}

struct BodyOut {
  std::int64_t id;
  Vec3<double> position, velocity, omega;
  Quat<double> orientation;
};

struct EnergyOut {
  std::int64_t id;
  double kinetic, gravity, wall;
};

template <class Real>
struct ContactOut {
  std::int64_t a, b, age;
  Vec3<Real> pa, pb, n;
  Real distance;
  double energy;
};

// Collective: every rank's bodies on rank 0 in id order, over `start` (its radii and shape rows).
inline DemBodies bodies_on_root(const Session& session, const std::vector<BodyOut>& mine,
                                const DemBodies& start) {
  const std::vector<BodyOut> all = gather_records(session, mine);
  if (session.rank() != 0) return {};
  DemBodies out = start;
  if (out.velocity.empty()) out.velocity.assign(out.size(), {0, 0, 0});
  if (out.angular_velocity.empty()) out.angular_velocity.assign(out.size(), {0, 0, 0});
  for (const BodyOut& r : all) {
    const std::size_t i = static_cast<std::size_t>(r.id);
    out.position[i] = r.position;
    out.velocity[i] = r.velocity;
    out.angular_velocity[i] = r.omega;
    if (!out.orientation.empty()) out.orientation[i] = r.orientation;
  }
  return out;
}

template <class Real>
void sort_by_pair(std::vector<ContactOut<Real>>& rows) {
  std::sort(rows.begin(), rows.end(), [](const ContactOut<Real>& x, const ContactOut<Real>& y) {
    return x.a < y.a || (x.a == y.a && x.b < y.b);
  });
}

// Collective: the energies on rank 0 (the others: zero), summed in the one-rank order (bodies by id,
// contacts by pair), from every rank's owned bodies and its contacts (each pair on one rank).
template <class Real>
DemEnergies energies_on_root(const Session& session, const std::vector<EnergyOut>& mine,
                             const std::vector<ContactOut<Real>>& rows, bool walls) {
  std::vector<EnergyOut> bodies = gather_records(session, mine);
  std::vector<ContactOut<Real>> contacts = gather_records(session, rows);
  DemEnergies e;
  if (session.rank() != 0) return e;
  std::sort(bodies.begin(), bodies.end(), [](const EnergyOut& x, const EnergyOut& y) { return x.id < y.id; });
  sort_by_pair(contacts);
  e.kinetic = dem::tree_sum(bodies.size(), [&](std::size_t i) { return bodies[i].kinetic; });
  e.gravity = dem::tree_sum(bodies.size(), [&](std::size_t i) { return bodies[i].gravity; });
  e.elastic = dem::tree_sum(contacts.size(), [&](std::size_t k) { return contacts[k].energy; }) +
              (walls ? dem::tree_sum(bodies.size(), [&](std::size_t i) { return bodies[i].wall; }) : 0.0);
  return e;
}

// Collective: the contacts of every rank on rank 0, sorted, with age (previous_row: the pair's row in
// the step before, found among `previous`, that step's keys gathered by keys_on_root).
template <class Real>
Contacts<Real> contacts_on_root(const Session& session, const std::vector<ContactOut<Real>>& rows,
                                const std::vector<PairKey>& previous) {
  std::vector<ContactOut<Real>> all = gather_records(session, rows);
  Contacts<Real> c;
  if (session.rank() != 0) return c;
  sort_by_pair(all);
  c.resize(all.size(), FieldSet{false, true});
  for (std::size_t k = 0; k < all.size(); ++k) {
    const ContactOut<Real>& r = all[k];
    c.id_a[k] = r.a;
    c.id_b[k] = r.b;
    c.position_on_a[k] = r.pa;
    c.position_on_b[k] = r.pb;
    c.normal_on_b[k] = r.n;
    c.distance[k] = r.distance;
    c.age[k] = r.age;
    const PairKey key{r.a, r.b};
    const auto at = std::lower_bound(previous.begin(), previous.end(), key);
    c.previous_row[k] = at != previous.end() && *at == key ? std::int64_t(at - previous.begin()) : -1;
  }
  c.history = true;
  return c;
}

// Collective: every rank's pair keys on rank 0, sorted.
inline std::vector<PairKey> keys_on_root(const Session& session, const std::vector<PairKey>& mine) {
  std::vector<PairKey> all = gather_records(session, mine);
  std::sort(all.begin(), all.end());
  return all;
}

}  // namespace cg::sim
