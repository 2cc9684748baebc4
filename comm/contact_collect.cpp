// Contacts collected from every rank (see contact_collect.hpp): gathered to rank 0, or exchanged by
// id_a range; then the k-way merge of the sorted runs (decomposition/contact_merge.hpp).
#include "contact_collect.hpp"

#include <cstdio>
#include <numeric>
#include <type_traits>

#include "agreed_stage.hpp"
#include "contact_merge.hpp"
#include "timing.hpp"
#include "transport.hpp"

namespace cg {
namespace {

// Element pointers of every field of `c`, in table order (the optional ones when `full`).
template <class Real>
std::vector<unsigned char*> field_bytes(Contacts<Real>& c, bool full) {
  std::vector<unsigned char*> p;
  for_each_contact_field(
      c, full, [&](auto, auto& column) { p.push_back(reinterpret_cast<unsigned char*>(column.data())); });
  return p;
}

// The k-way merge of the sorted runs by (id_a, id_b) into `out`, exact duplicates removed; returns
// how many (expected 0). `local` holds the runs that are views into it; it is released. A single run
// is already merged: `local` is moved into `out`, not copied (the only run of one rank is the whole of
// `local`: a copy of K rows saved).
template <class Real>
std::uint64_t merge_runs(std::vector<ContactRunView<Real>>& runs, Contacts<Real>& local, Contacts<Real>& out,
                         int threads) {
  const bool full = local.full;
  if (runs.size() == 1) {
    out = std::move(local);
    runs.clear();
    return 0;
  }
  std::uint64_t total = 0;
  for (const ContactRunView<Real>& r : runs) total += r.n;
  Contacts<Real> merged;
  merged.resize(total, full);
  const int parts = total < (std::uint64_t(1) << 15) ? 1 : 4 * threads;  // a few per thread: balance
  const std::uint64_t duplicates = merge_contact_runs_into<Real>(runs, merged, full, parts, threads);
  runs.clear();
  local = Contacts<Real>{};
  out = std::move(merged);
  return duplicates;
}

}  // namespace

template <class Real>
CollectedContacts<Real> gather_contacts(const Session& session, Contacts<Real>&& local, std::uint64_t bodies,
                                        const CollectOptions& options) {
  const detail::Comm comm(session);
  const int ranks = comm.size(), me = comm.rank(), threads = options.threads;
  const bool full = local.full, root = me == 0;
  CollectedContacts<Real> result;
  // ---- gather: each field to rank 0, straight into per-rank receive buffers ---------------------
  auto t0 = WallClock::now();
  const std::vector<std::uint64_t> counts = comm.allgather<std::uint64_t>(local.size());
  const std::size_t p = counts.size();
  std::vector<ContactRunView<Real>> runs;
  std::vector<Contacts<Real>> received(root ? p : 0);  // rank 0: rank r's run (r >= 1)
  if (root) {
    runs.resize(p);
    runs[0] = contact_run_view(local, full);  // rank 0's own run stays in place
    for (std::size_t r = 1; r < p; ++r) {
      received[r].resize(counts[r], full);
      runs[r] = contact_run_view(received[r], full);
    }
  }
  // each field to rank 0, one tag per field, straight into rank r's received run
  std::vector<std::vector<unsigned char*>> into(root ? p : 0);
  for (std::size_t r = 1; root && r < p; ++r) into[r] = field_bytes(received[r], full);
  int f = 0;
  for_each_contact_field(local, full, [&](auto, auto& column) {
    using T = std::remove_reference_t<decltype(column[0])>;
    std::vector<T*> t(root ? p : 0, nullptr);
    for (std::size_t r = 1; root && r < p; ++r)
      t[r] = reinterpret_cast<T*>(into[r][static_cast<std::size_t>(f)]);
    comm.gather_to_root(column.data(), counts, t, options.max_message_bytes, detail::k_gather_tag + f);
    ++f;
  });
  if (!root) local = Contacts<Real>{};
  result.transfer_seconds = seconds_since(t0);

  // ---- merge (rank 0): k-way merge of the sorted runs, duplicates removed and counted -----------
  t0 = WallClock::now();
  agreed_stage(session, "merge", [&] {
    if (!root) return;
    result.duplicates_removed = merge_runs(runs, local, result.contacts, threads);
    const std::string line = "merge: " + std::to_string(result.contacts.size()) + " contacts from " +
                             std::to_string(ranks) + " rank(s), " +
                             std::to_string(result.duplicates_removed) + " duplicate(s) removed (expected 0)";
    if (options.log) {
      options.log(line);
    } else if (result.duplicates_removed > 0) {  // a warning nobody asked for must still be seen
      std::fprintf(stderr, "%swarning: %s\n", session.prefix().c_str(), line.c_str());
    }
  });
  result.merge_seconds = seconds_since(t0);
  result.total_contacts = session.sum(me == 0 ? result.contacts.size() : 0);
  result.first_row = me == 0 ? 0 : result.total_contacts;
  result.id_begin = me == 0 ? 0 : bodies;
  result.id_end = bodies;
  result.contacts.full = full;
  return result;
}

template <class Real>
CollectedContacts<Real> exchange_contacts(const Session& session, Contacts<Real>&& local,
                                          std::uint64_t n_global, const CollectOptions& options) {
  const detail::Comm comm(session);
  const int ranks = comm.size(), me = comm.rank(), threads = options.threads;
  const std::size_t p = static_cast<std::size_t>(ranks), mine = static_cast<std::size_t>(me);
  const bool full = local.full;
  CollectedContacts<Real> result;
  // the id_a range of rank d: the rows it read
  auto id_begin = [&](std::size_t d) { return n_global * d / p; };
  result.id_begin = id_begin(mine);
  result.id_end = id_begin(mine + 1);

  // ---- exchange: each destination's slice of every field, straight from the arrays --------------
  auto t0 = WallClock::now();
  std::vector<std::uint64_t> split(p + 1, 0), send_counts(p, 0);
  agreed_stage(session, "exchange", [&] {
    // sorted by (id_a, id_b), so rank d's rows are one sub-range
    split[p] = local.size();
    for (std::size_t d = 1; d < p; ++d) {
      const auto at =
          std::lower_bound(local.id_a.begin(), local.id_a.end(), static_cast<std::int64_t>(id_begin(d)));
      split[d] = static_cast<std::uint64_t>(at - local.id_a.begin());
    }
    for (std::size_t d = 0; d < p; ++d) send_counts[d] = split[d + 1] - split[d];
  });
  const std::vector<std::uint64_t> recv_counts = comm.alltoall_counts(send_counts);
  std::vector<ContactRunView<Real>> runs(p);
  std::vector<Contacts<Real>> received(p);  // rank r's part of this rank's id range (r != me)
  std::vector<detail::Comm::RowField> fields;
  agreed_stage(session, "exchange", [&] {
    for (std::size_t r = 0; r < p; ++r) {
      if (r == mine) {  // this rank's own part stays where it is
        runs[r] = contact_run_view(local, full, split[mine], send_counts[mine]);
        continue;
      }
      received[r].resize(recv_counts[r], full);
      runs[r] = contact_run_view(received[r], full);
    }
    // one RowField per contact field, in table order: sent from `local`, received into `received`
    for_each_contact_field(local, full, [&](auto, auto& column) {
      detail::Comm::RowField& field = fields.emplace_back();
      field.send = reinterpret_cast<const unsigned char*>(column.data());
      field.row_bytes = sizeof(column[0]);
      field.into.assign(p, nullptr);
    });
    for (std::size_t r = 0; r < p; ++r) {
      if (r == mine) continue;
      const std::vector<unsigned char*> to = field_bytes(received[r], full);
      for (std::size_t f = 0; f < fields.size(); ++f) fields[f].into[r] = to[f];
    }
  });
  comm.exchange_rows(fields, split, recv_counts, options.max_message_bytes, detail::k_exchange_tag);
  result.transfer_seconds = seconds_since(t0);

  // ---- merge: the P sorted runs of this rank's id range, duplicates removed and counted ----------
  t0 = WallClock::now();
  std::uint64_t duplicates = 0;
  agreed_stage(session, "merge", [&] { duplicates = merge_runs(runs, local, result.contacts, threads); });
  result.merge_seconds = seconds_since(t0);
  result.duplicates_removed = session.sum(duplicates);
  const std::vector<std::uint64_t> counts = comm.allgather<std::uint64_t>(result.contacts.size());
  result.first_row = std::accumulate(counts.begin(), counts.begin() + me, std::uint64_t{0});
  result.total_contacts = std::accumulate(counts.begin(), counts.end(), std::uint64_t{0});
  const std::string line = "merge: " + std::to_string(result.total_contacts) + " contacts in " +
                           std::to_string(ranks) + " id range(s), " +
                           std::to_string(result.duplicates_removed) + " duplicate(s) removed (expected 0)";
  if (me == 0) {
    if (options.log) {
      options.log(line);
    } else if (result.duplicates_removed > 0) {  // a warning nobody asked for must still be seen
      std::fprintf(stderr, "%swarning: %s\n", session.prefix().c_str(), line.c_str());
    }
  }
  result.contacts.full = full;
  return result;
}

template CollectedContacts<float> gather_contacts(const Session&, Contacts<float>&&, std::uint64_t,
                                                  const CollectOptions&);
template CollectedContacts<double> gather_contacts(const Session&, Contacts<double>&&, std::uint64_t,
                                                   const CollectOptions&);
template CollectedContacts<float> exchange_contacts(const Session&, Contacts<float>&&, std::uint64_t,
                                                    const CollectOptions&);
template CollectedContacts<double> exchange_contacts(const Session&, Contacts<double>&&, std::uint64_t,
                                                     const CollectOptions&);

}  // namespace cg
