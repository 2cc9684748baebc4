#pragma once
// distributed_detect: one detection over every rank of a Session, its options and its result (the
// library's entry to the run; the `detect` command is this plus the write and the summary,
// run/pipeline.hpp). src/run/pipeline.cpp sequences its stages, each one call there:
//   read → frame → slabs → distribute → exchange ghosts → detect → collect contacts
// (one rank: the same stages, with nothing to send). Each stage, with the name its time is reported
// under (RunStage, run_stage.hpp; each the maximum over ranks):
//   read_partition    [read] rank r's partition is rows [N·r/P, N·(r+1)/P) of /spheres; it reads only
//                     those (SceneRead::own_rows) or all rows (SceneRead::all_rows, the default when all
//                     ranks share one node: one page cache, so N rows read P times cost memory
//                     bandwidth, not disk, and no body moves between ranks; the faster read on one
//                     host, BENCHMARKS.md §4).
//   agree_frame       [read] global bounds by an all-gather of the partitions' Bounds, folded with
//                     Bounds::merge in rank order; the frame = make_frame(global bounds) — the frame a
//                     single-rank run builds — so every rank computes bit-identical local coordinates
//                     and contact data; the slab axis (largest extent unless forced); the ghost rule
//                     (GhostRule, decomposition/slab_decomposition.hpp: a body's ghost width is its
//                     radius + that of the largest partner that may anchor its pairs + a rounding
//                     margin: the few wide bodies go as far as they reach, the narrow ones' halos stay
//                     small) and the broad phase (`auto`: from the global bounds).
//   make_slabs        [redistribute] cuts from the quantiles of a regular sample of centre
//                     coordinates gathered to every rank (balance = count; the P-1 quantiles are
//                     selected, not the sample sorted) or equal widths (balance = width): identical on
//                     all ranks.
//   distribute        [redistribute] all rows: each rank selects, in one parallel pass over all rows,
//                     its owned bodies and its ghosts (decomposition/assemble), already in id order.
//                     Own rows: every body to its owner (decomposition/routing: to_owner, count → scan
//                     → fill in parallel; comm/distribute: Alltoall counts, Alltoallv records).
//   exchange_ghosts   [halo] own rows: every owned body to each other rank within its ghost width
//                     (routing: to_ghost_ranks_by, the rule of make_halo_plan; comm/halo_exchange:
//                     exchange_with_ghost_ranks, counts by Alltoall, every Irecv posted, every Isend, one
//                     Waitall). All rows: nothing.
//   detect_local      [detect] own rows: owned + ghosts merged by id (assemble: merge_by_id); report
//                     mask = owned, and wide (kWideBit); Engine<Real>::detect with the shared frame.
//                     The owner of a pair's anchor (the smaller id, or the narrow body of a wide and a
//                     narrow one) reports it, so each contact is found by exactly one rank.
//   collect_contacts  [gather | exchange, merge] (DistributedOptions::output, comm/contact_collect):
//                     gathered to rank 0, or exchanged by id_a range, then k-way merged; rank r's rows
//                     are rows [first_row, first_row + size) of the single-rank result, which
//                     src/run/contact_file_shared writes into one file at once.
// One rank takes the same stages with nothing to send: reading all rows, its one slab owns every row,
// so the rows as read are the engine's input (ids implied, all pairs reported), and its single run of
// contacts is the result (moved, not merged).
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
#include "resident_steps.hpp"
#include "run/run_stage.hpp"
#include "session.hpp"
#include "slab_decomposition.hpp"

namespace cg {

// The options of a run, typed once by the CLI (the words of its options in the comments).

// --axis: the slab axis (automatic: the largest extent of the global bounds).
enum class SlabAxis : int { automatic = -1, x = 0, y = 1, z = 2 };

// --write: where the contacts end up (see comm/contact_collect.hpp).
enum class ContactOutput {
  gather,  // gather: all on rank 0 (gathered and merged there); stages ... gather, merge
  ranks,  // ranks: each rank the rows with id_a in its range [N·r/P, N·(r+1)/P); stages ... exchange, merge
};

// --read: how the ranks get their bodies (see read_partition above).
enum class SceneRead {
  automatic,  // auto: all_rows when all ranks share one node (one page cache), else own_rows
  own_rows,   // own: rank r reads rows [N·r/P, N·(r+1)/P); bodies move to their owners, ghosts by halo
              // exchange
  all_rows,   // all: every rank reads all rows and keeps its owned bodies and its ghosts: no body moves
};

struct DistributedOptions {
  EngineOptions engine;  // backend, fields, cell_size and cell_choice, threads (also the
                         // pipeline's host loops; 0: the hardware threads shared equally among
                         // the ranks on the node), device
  SlabAxis axis = SlabAxis::automatic;
  Balance balance = Balance::count;
  std::uint64_t max_sample = 1u << 20;         // quantile sample size (all bodies when N <= it)
  std::uint64_t max_message_bytes = 1u << 30;  // per-message gather/exchange size (tests make it tiny)
  ContactOutput output = ContactOutput::gather;
  SceneRead read = SceneRead::automatic;
  int resident_steps = 0;   // > 0: then that many resident steps (comm/resident_steps.hpp)
  StepMotion step_motion;   // how the bodies change between those steps (--spin, --drift)
  std::string final_scene;  // not empty: the last step's bodies written there as a scene (rank 0)
  // Info lines (rank 0 only): the merge line with the duplicate count. When empty, the line is
  // printed to stderr as a warning only if duplicates were removed.
  std::function<void(const std::string&)> log;
  // --memory-limit: the bytes a rank's detection may hold (0: no limit, one piece). Above it the rank
  // detects in slabs that fit (decomposition/pieces.hpp), with the same contacts; on CUDA the engine's
  // workspace is capped there too (CONTACTGRID_DEVICE_MEMORY_LIMIT, the smaller of the two).
  std::uint64_t memory_limit = 0;
};

// Throws UsageError naming the bad option (for library callers; the CLI has typed them already).
// Called by distributed_detect before any communication.
void check_options(const DistributedOptions& options);

template <class Real>
struct DistributedResult {
  // gather: rank 0 holds all contacts in docs/FORMAT.md §2 order, the others none. ranks: this rank's
  // rows [first_row, first_row + contacts.size()) of that order: every contact with id_a in
  // [id_begin, id_end).
  Contacts<Real> contacts;
  std::uint64_t first_row = 0;             // gather: 0 on rank 0, total_contacts elsewhere
  std::uint64_t total_contacts = 0;        // K, on every rank
  std::uint64_t id_begin = 0, id_end = 0;  // gather: [0, N) on rank 0, [N, N) elsewhere
  RunTimes
      times;  // read, redistribute, halo, detect (+ the engine's), gather|exchange, merge (max over ranks)
  std::uint64_t duplicates_removed = 0;        // gather: rank 0; ranks: summed, every rank (expected 0)
  std::uint64_t bodies = 0;                    // global body count
  std::uint64_t ellipsoids = 0;                // of which ellipsoids (the scene's)
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
  EngineStats stats;  // entries, pair tests, narrow_fallbacks, narrow_unconverged summed over ranks
  // --memory-limit (DistributedOptions::memory_limit; 0: none): the most pieces a rank's detection
  // took, and the most detections (pieces + the tries that did not fit) a rank ran.
  std::uint64_t memory_limit = 0, pieces = 1, piece_detections = 1;
  StepStats steps;  // resident steps (steps == 0: none ran)
  // The device made ready while the scene was read (kernels/device_warm_up.hpp; rank 0's): its
  // thread's seconds, those of the context's creation among them, and how long the run then waited
  // for it (0: none ran).
  double warm_up = 0, warm_up_context = 0, warm_up_wait = 0;
};

// Collective over `session`: every rank calls it with the same arguments. The stages read … collect
// of a detect run (no file written).
template <class Real>
DistributedResult<Real> distributed_detect(Session& session, const std::string& scene_path,
                                           const DistributedOptions& options);

extern template DistributedResult<float> distributed_detect<float>(Session&, const std::string&,
                                                                   const DistributedOptions&);
extern template DistributedResult<double> distributed_detect<double>(Session&, const std::string&,
                                                                     const DistributedOptions&);

}  // namespace cg
