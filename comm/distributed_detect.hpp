#pragma once
// Contact detection over the ranks of a Session: the MPI slab decomposition wrapped around the
// single-rank Engine. g++-safe public header (no <mpi.h>).
//
// Pipeline (each stage's time is reported as the maximum over ranks):
//   read          rank r's partition is rows [N·r/P, N·(r+1)/P) of /spheres; it reads only those
//                 (SceneRead::own_rows) or every row (SceneRead::every_row, the default when all
//                 ranks share one node: one page cache, so N rows read P times cost memory bandwidth,
//                 not disk, and no body moves between ranks; 2^26 on 2 GPUs of one host, 962ecd7: 2.25–2.40 s
//                 against 2.59–3.08 s, BENCHMARKS.md §4). Global bounds by an all-gather of
//                 the partitions' Bounds, folded with Bounds::merge in rank order; the frame =
//                 make_frame(global bounds) — the frame a single-rank run builds — so every rank
//                 computes bit-identical local coordinates and contact data.
//   every_row     redistribute = each rank selects, in one parallel pass over all rows, its owned
//                 bodies and the others within the ghost width of its slab (the same owner() and
//                 for_each_ghost_rank() tests as below), already in id order; halo takes no time.
//   redistribute  slab axis (largest extent unless forced); cuts from the quantiles of a regular
//                 sample of centre coordinates gathered to every rank (balance = count) or equal widths
//                 (balance = width): identical on all ranks (the P-1 quantiles are selected, not the
//                 sample sorted); every body to its owner (Alltoall counts, Alltoallv records packed
//                 by destination in one parallel count → scan → fill, no index list).
//   halo          ghost plan (SlabDecomposition::for_each_ghost_rank, ghost width = 2·r_max + rounding
//                 margin; the same plan as decomposition/make_halo_plan, packed in parallel);
//                 counts by Alltoall, then every Irecv posted, every Isend, one Waitall.
//   detect        owned + ghosts in global id order (owned bodies arrive in id order, grouped by
//                 source rank; the ghost groups are merged, then merged with them in parallel straight
//                 into the engine's arrays); report mask = owned; Engine<Real>::detect with the
//                 shared frame. The owner of the smaller id reports a pair, so each contact is
//                 found by exactly one rank.
// Then the contacts, in one of two modes (DistributedOptions::output):
//  ContactOutput::id_ranges (the CLI's detect): no rank holds them all.
//   exchange      rank r is responsible for the output rows with id_a in [N·r/P, N·(r+1)/P) (the
//                 rows it read: known before detection). A rank's contacts are sorted by
//                 (id_a, id_b), so its part for each destination is one sub-range (binary search):
//                 counts by Alltoall, then every field's slice sent straight from the arrays (every
//                 Irecv posted, every Isend, one Waitall; messages of at most max_message_bytes, so
//                 no count exceeds 2^31), into one receive array per source and field (the rank's
//                 own part stays in place).
//   merge         every rank: k-way merge of its P received runs by (id_a, id_b), duplicates removed
//                 (summed over ranks: expected 0); an all-gather of the merged counts gives each
//                 rank its first output row and the total K. Rank r's rows are rows
//                 [first_row, first_row + size) of the single-rank result; comm/distributed_write
//                 writes them into one file at once.
//  ContactOutput::root (tests, library users who want everything in one place):
//   gather        counts, then each field to rank 0 point to point, straight into one receive array
//                 per rank and field (rank 0's own run stays in place), in messages of at most
//                 max_message_bytes (so no count exceeds 2^31).
//   merge         rank 0: k-way merge of the P sorted runs by (id_a, id_b), exact duplicates removed
//                 and counted (expected 0) — the result of decomposition/merge_contact_runs, computed
//                 in parallel over key ranges straight into the result.
// With one rank (laptop mode or np 1) nothing is exchanged or copied: the rows as read go to the
// engine (ids implied, all pairs reported) and its contacts are the result; the stages are still
// reported (redistribute, halo, exchange/gather and merge take no time).
//
// Resident steps (DistributedOptions::resident_steps, after the above): what a simulation that keeps
// its bodies on the GPUs pays per step for the same decomposition. Each rank keeps its owned bodies
// in its engine (A: Engine::set_resident, its GPU), ordered [sent down only][sent both ways][sent up
// only][interior], so that every halo message is one contiguous range, and a second engine (B)
// holds [ghosts from lower ranks][the boundary owned bodies (those sent anywhere)][ghosts from higher
// ranks]. A step: the boundary rows come out of A (device → host); A detects all pairs of the owned
// bodies on a second thread while this thread exchanges the halo (host-staged: Debian's Open MPI is
// not CUDA-aware) and writes B's rows (host → device); then B detects its pairs with the report
// mask "first of the pair in (owner rank, row) order is owned" and kPairedBit on the boundary owned
// bodies (their mutual pairs are A's). An interior body is farther than the ghost width from every
// other slab, so it touches no ghost: A + B find every contact of the rank exactly once. Every step
// checks that the contacts summed over ranks equal K, and the last step's pairs the run's (an
// order-free hash; CUDA: downloaded after the timing). A rank sends its whole downward set to every lower
// rank that needs any of it (upward likewise): with slabs thinner than the ghost width a superset of the
// ghosts, which changes no contact. Bodies do not move between steps (no migration), so a step is the
// "everything recomputed, halo refreshed" cost; contacts stay where they were computed.
//
// Errors: options are validated before any communication. An error in a stage on any rank (bad
// input, I/O, CUDA, memory) is agreed on at the end of the stage (Session::agree): every rank throws
// the same exception, "[rank r/N] <stage>: <cause>". A failing MPI call (CommFailure) leaves other
// ranks possibly waiting, so it ends the job with Session::abort (exit code 5).
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "engine.hpp"
#include "session.hpp"
#include "slab_decomposition.hpp"

namespace cg {

// Where the contacts end up (see the file comment).
enum class ContactOutput {
  root,       // all on rank 0 (gather + merge there); stages ... gather, merge
  id_ranges,  // each rank: the rows with id_a in its range [N·r/P, N·(r+1)/P); stages ... exchange, merge
};

// How the ranks get their bodies (see the file comment).
enum class SceneRead {
  automatic,  // every_row when all ranks share one node (one page cache), else own_rows
  own_rows,   // rank r reads rows [N·r/P, N·(r+1)/P); bodies move to their owners, ghosts by halo exchange
  every_row,  // every rank reads all rows and keeps its owned bodies and its ghosts: no body moves
};

struct DistributedOptions {
  EngineOptions engine;  // backend, fields, cell_size and cell_choice, threads (also the
                         // pipeline's host loops; 0: the hardware threads shared equally among
                         // the ranks on the node), device
  int axis = -1;         // slab axis: 0 x, 1 y, 2 z, -1 largest extent (parse_axis)
  Balance balance = Balance::count;
  std::uint64_t max_sample = 1u << 20;         // quantile sample size (all bodies when N <= it)
  std::uint64_t max_message_bytes = 1u << 30;  // per-message gather/exchange size (tests make it tiny)
  ContactOutput output = ContactOutput::root;
  SceneRead read = SceneRead::automatic;
  int resident_steps = 0;  // > 0: then that many resident steps (see the file comment)
  // Info lines (rank 0 only): the merge line with the duplicate count. When empty, the line is
  // printed to stderr as a warning only if duplicates were removed.
  std::function<void(const std::string&)> log;
};

// Throws UsageError naming the bad option. Called by distributed_detect before any communication.
void validate(const DistributedOptions& options);

// Resident steps (DistributedOptions::resident_steps): per step the maximum over ranks, then the
// median over the steps.
struct StepStats {
  int steps = 0;
  std::uint64_t contacts = 0;   // per step, summed over ranks (checked equal to the file's K)
  std::uint64_t halo_rows = 0;  // ghost rows refreshed per step, summed over ranks
  double setup = 0;             // layout, first exchange, upload (once, max over ranks)
  double halo = 0;              // ghost refresh: boundary rows out of the GPU, MPI, ghost rows into it
  double interior = 0;          // the owned bodies alone (all their pairs), overlapping the halo
  double boundary = 0;          // the boundary owned bodies against the ghosts, after the halo
  double step = 0;              // wall time of a step
  StageTimes stages;            // the engine's stages of the interior detection
};

template <class Real>
struct DistributedResult {
  // root: rank 0 holds all contacts in CONTRACT §2 order, the others none. id_ranges: this rank's
  // rows [first_row, first_row + contacts.size()) of that order: every contact with id_a in
  // [id_begin, id_end).
  Contacts<Real> contacts;
  std::uint64_t first_row = 0;             // root: 0 on rank 0, total_contacts elsewhere
  std::uint64_t total_contacts = 0;        // K, on every rank
  std::uint64_t id_begin = 0, id_end = 0;  // root: [0, N) on rank 0, [N, N) elsewhere
  StageTimes times;  // read, redistribute, halo, detect, gather|exchange, merge (max over ranks, s)
  std::uint64_t duplicates_removed = 0;        // root: rank 0; id_ranges: summed, every rank (expected 0)
  std::uint64_t bodies = 0;                    // global body count
  std::uint64_t ghosts = 0;                    // ghosts held, summed over ranks
  std::uint64_t owned_min = 0, owned_max = 0;  // owned bodies per rank: balance of the slabs
  double cell_size = 0;                        // the frame's cell edge
  Frame frame;                                 // the shared frame
  int ranks = 1;
  SceneRead read = SceneRead::own_rows;  // the read mode used (never automatic)
  int axis = 0;                          // the slab axis used
  std::vector<double> cuts;              // the P-1 slab cuts
  Backend backend = Backend::cpu;        // the engine's resolved backend (this rank)
  int threads = 1;                       // host threads of this rank (engine and host loops)
  EngineStats stats;                     // entries and pair tests summed over ranks
  StepStats steps;                       // resident steps (steps == 0: none ran)
};

// Collective over `session`: every rank calls it with the same arguments. See the file comment.
template <class Real>
DistributedResult<Real> distributed_detect(Session& session, const std::string& scene_path,
                                           const DistributedOptions& options);

extern template DistributedResult<float> distributed_detect<float>(Session&, const std::string&,
                                                                   const DistributedOptions&);
extern template DistributedResult<double> distributed_detect<double>(Session&, const std::string&,
                                                                     const DistributedOptions&);

}  // namespace cg
