#pragma once
// What the ranks of `contactgrid simulate` under mpirun send each other and gather on rank 0, shared
// by both ways a rank computes its bodies (distributed_dem.hpp: the forces on the host; resident_dem.hpp:
// each rank's rows where its backend computes): records between ranks as bytes, and rank 0's frame
// bodies, energies (summed in the one-rank order of core/dem_sum.hpp) and contacts from every
// rank's rows; the one-rank order's sums from what each rank sums of its own items (tree_sums_on_root).
#include <algorithm>
#include <array>
#include <string>
#include <type_traits>
#include <vector>

#include "collectives.hpp"
#include "core/dem_sum.hpp"
#include "dem.hpp"
#include "errors.hpp"
#include "session.hpp"

namespace cg::sim {

// Records between ranks (collectives.hpp: alltoallv_records, no staging copy), grouped by
// destination rank; the result grouped by source rank (received: how many from each).
template <class T>
std::vector<T> exchange_records(const Session& session, const std::vector<T>& send,
                                const std::vector<std::uint64_t>& counts,
                                std::vector<std::uint64_t>* received = nullptr) {
  static_assert(std::is_trivially_copyable_v<T>);
  const std::vector<std::uint64_t> from = alltoall_counts(session, counts);
  std::uint64_t total = 0;
  for (const std::uint64_t c : from) total += c;
  std::vector<T> out(total);
  alltoallv_records(session, sizeof(T), send.data(), counts, out.data(), from);
  if (received) *received = from;
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

// A log row's sums over the ranks (rank 0's energies; the others: zero).
struct LogSums {
  DemEnergies energies;
  std::uint64_t contacts = 0;
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

// Collective: every rank's bodies on rank 0 in id order into `out` (made from `start`, its radii
// and shape rows, when it does not hold them yet: a frame's bodies kept between frames take only
// the motion again); the others: `out` untouched.
inline void bodies_on_root(const Session& session, const std::vector<BodyOut>& mine, const DemBodies& start,
                           DemBodies& out) {
  const std::vector<BodyOut> all = gather_records(session, mine);
  if (session.rank() != 0) return;
  if (out.size() != start.size() || out.radius.size() != start.size()) {
    out = start;
    if (out.velocity.empty()) out.velocity.assign(out.size(), {0, 0, 0});
    if (out.angular_velocity.empty()) out.angular_velocity.assign(out.size(), {0, 0, 0});
  }
  const bool oriented = !out.orientation.empty();
  const std::ptrdiff_t m = static_cast<std::ptrdiff_t>(all.size());
#pragma omp parallel for schedule(static) if (m > 65536)
  for (std::ptrdiff_t k = 0; k < m; ++k) {  // each id once: no two threads write one body
    const BodyOut& r = all[std::size_t(k)];
    const std::size_t i = static_cast<std::size_t>(r.id);
    out.position[i] = r.position;
    out.velocity[i] = r.velocity;
    out.angular_velocity[i] = r.omega;
    if (oriented) out.orientation[i] = r.orientation;
  }
}

// The same into a new DemBodies (the others: empty).
inline DemBodies bodies_on_root(const Session& session, const std::vector<BodyOut>& mine,
                                const DemBodies& start) {
  DemBodies out;
  bodies_on_root(session, mine, start, out);
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

// ---- the one-rank order's sums from each rank's own items -----------------------------------------
// The tree sum of core/dem_sum.hpp over a global sequence of `total` items (S series at once), whose
// items lie on several ranks, each position on one: a rank sends rank 0 each first-level chunk it
// holds whole as that chunk's sums (the same bits: the chunk's items in order, from 0) and the items
// of the other chunks one by one; rank 0 sums those chunks from their items in position order, then
// the tree's further levels. The one-rank bits from about total / kEnergyChunk records, not total.

template <int S>
struct SumRecord {
  std::uint64_t index;  // whole: the chunk; else the item's position
  std::uint64_t whole;  // 1: a chunk's sums; 0: an item's values
  std::array<double, S> v;
};

// This rank's records of its items at `position` (strictly ascending, each < total) with `values`.
template <int S>
std::vector<SumRecord<S>> sum_records(std::uint64_t total, const std::vector<std::uint64_t>& position,
                                      const std::vector<std::array<double, S>>& values) {
  if (position.size() != values.size())
    throw Error("simulate: the sums' positions differ in number from their values: internal error");
  std::vector<SumRecord<S>> out;
  const std::uint64_t chunk = dem::kEnergyChunk;
  const std::size_t m = position.size();
  for (std::size_t j = 0; j < m;) {
    const std::uint64_t c = position[j] / chunk, first = c * chunk, end = std::min(total, first + chunk);
    std::size_t e = j;
    while (e < m && position[e] / chunk == c) {
      if (position[e] >= total || (e > 0 && position[e] <= position[e - 1]))
        throw Error("simulate: the sums' positions are not ascending below their total: internal error");
      ++e;
    }
    if (e - j == end - first) {  // the whole chunk (distinct positions in it)
      SumRecord<S> r{c, 1, {}};
      for (int s = 0; s < S; ++s)
        r.v[std::size_t(s)] =
            dem::chunk_sum(c, total, [&](std::size_t i) { return values[j + (i - first)][s]; });
      out.push_back(r);
    } else {
      for (std::size_t k = j; k < e; ++k) out.push_back({position[k], 0, values[k]});
    }
    j = e;
  }
  return out;
}

// The tree's sums of every rank's records (Error when they do not give each item once).
template <int S>
std::array<double, S> sums_from_records(std::uint64_t total, const std::vector<SumRecord<S>>& records) {
  std::array<double, S> out{};
  if (total == 0) {
    if (!records.empty()) throw Error("simulate: sums of no items came with records: internal error");
    return out;
  }
  const std::uint64_t chunk = dem::kEnergyChunk;
  const std::size_t chunks = dem::energy_chunks(total);
  std::vector<std::array<double, S>> level(chunks);
  std::vector<std::uint8_t> set(chunks, 0);
  std::vector<SumRecord<S>> items;
  for (const SumRecord<S>& r : records) {
    if (!r.whole) {
      items.push_back(r);
      continue;
    }
    if (r.index >= chunks || set[r.index])
      throw Error("simulate: a chunk of the sums came twice: internal error");
    set[r.index] = 1;
    level[r.index] = r.v;
  }
  std::sort(items.begin(), items.end(),
            [](const SumRecord<S>& x, const SumRecord<S>& y) { return x.index < y.index; });
  std::size_t j = 0;
  for (std::size_t c = 0; c < chunks; ++c) {
    if (set[c]) continue;
    const std::uint64_t first = c * chunk, end = std::min(total, first + chunk);
    for (std::uint64_t i = first; i < end; ++i)
      if (j + (i - first) >= items.size() || items[j + (i - first)].index != i)
        throw Error("simulate: item " + std::to_string(i) +
                    " of the sums is missing or came twice: internal error");
    for (int s = 0; s < S; ++s)
      level[c][std::size_t(s)] =
          dem::chunk_sum(c, total, [&](std::size_t i) { return items[j + (i - first)].v[std::size_t(s)]; });
    j += end - first;
  }
  if (j != items.size()) throw Error("simulate: an item of the sums came twice: internal error");
  for (int s = 0; s < S; ++s)
    out[std::size_t(s)] =
        chunks == 1 ? level[0][std::size_t(s)]
                    : dem::tree_sum(chunks, [&](std::size_t c) { return level[c][std::size_t(s)]; });
  return out;
}

// Collective: the tree's sums on rank 0 (the others: zeros) of every rank's items (sum_records).
template <int S>
std::array<double, S> tree_sums_on_root(const Session& session, std::uint64_t total,
                                        const std::vector<std::uint64_t>& position,
                                        const std::vector<std::array<double, S>>& values) {
  const std::vector<SumRecord<S>> all = gather_records(session, sum_records<S>(total, position, values));
  if (session.rank() != 0) return {};
  return sums_from_records<S>(total, all);
}

// Where items per body lie in the one-rank order of items by body id (a contact by its smaller
// id, the owner's): a run of consecutive ids [begin, end) that one rank owns, with its items' count.
struct IdRun {
  std::int64_t begin, end;
  std::uint64_t items;
};

// This rank's runs of its owned `ids` (strictly ascending) with each id's `items`.
inline std::vector<IdRun> id_runs(const std::vector<std::int64_t>& ids,
                                  const std::vector<std::uint64_t>& items) {
  std::vector<IdRun> runs;
  for (std::size_t j = 0; j < ids.size(); ++j) {
    if (!runs.empty() && runs.back().end == ids[j]) {
      ++runs.back().end;
      runs.back().items += items[j];
    } else {
      runs.push_back({ids[j], ids[j] + 1, items[j]});
    }
  }
  return runs;
}

// The first position of each of `mine` among the items of every rank's runs `all` (which tile the
// ids 0 .. ids - 1: Error else), and the items' total.
inline std::vector<std::uint64_t> run_offsets(std::vector<IdRun> all, const std::vector<IdRun>& mine,
                                              std::uint64_t ids, std::uint64_t& total) {
  std::sort(all.begin(), all.end(), [](const IdRun& x, const IdRun& y) { return x.begin < y.begin; });
  std::vector<std::uint64_t> first(all.size());
  std::int64_t next = 0;
  total = 0;
  for (std::size_t r = 0; r < all.size(); ++r) {
    if (all[r].begin != next || all[r].end <= all[r].begin)
      throw Error("simulate: the ranks' bodies do not tile the ids at " + std::to_string(next) +
                  ": internal error");
    first[r] = total;
    total += all[r].items;
    next = all[r].end;
  }
  if (static_cast<std::uint64_t>(next) != ids)
    throw Error("simulate: the ranks' bodies do not tile the ids at " + std::to_string(next) +
                ": internal error");
  std::vector<std::uint64_t> out(mine.size());
  for (std::size_t r = 0; r < mine.size(); ++r) {
    const auto at = std::lower_bound(all.begin(), all.end(), mine[r].begin,
                                     [](const IdRun& x, std::int64_t b) { return x.begin < b; });
    if (at == all.end() || at->begin != mine[r].begin || at->end != mine[r].end || at->items != mine[r].items)
      throw Error("simulate: a rank's run of ids is not among the ranks': internal error");
    out[r] = first[std::size_t(at - all.begin())];
  }
  return out;
}

}  // namespace cg::sim
