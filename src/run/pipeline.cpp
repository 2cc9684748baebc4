// Sequencing of a contactgrid run. Reads like the data flow; each stage is one call:
//   read → frame → slabs → distribute → exchange ghosts → detect → collect contacts → write → summary
#include "run/pipeline.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <numeric>
#include <optional>

#include "agreed_stage.hpp"
#include "assemble.hpp"
#include "collectives.hpp"
#include "contact_collect.hpp"
#include "device_warm_up.hpp"
#include "distribute.hpp"
#include "halo_exchange.hpp"
#include "host_vector.hpp"
#include "io/contact_file.hpp"
#include "io/contacts_csv.hpp"
#include "io/inspect.hpp"
#include "io/scene_file.hpp"
#include "io/temp_output.hpp"
#include "node_threads.hpp"
#include "pieces.hpp"
#include "precision_choice.hpp"
#include "routing.hpp"
#include "run/contact_file_shared.hpp"
#include "run/progress.hpp"
#include "run/stage_clock.hpp"
#include "run/steps.hpp"
#include "run/stop.hpp"
#include "run/summary.hpp"
#include "run/test_fault.hpp"
#include "session.hpp"
#include "slab_decomposition.hpp"

namespace cg {

void check_options(const DistributedOptions& options) {
  const EngineOptions& e = options.engine;
  const int axis = static_cast<int>(options.axis);
  if (axis < -1 || axis > 2) {
    throw UsageError("--axis: " + std::to_string(axis) + " is not x, y, z or auto");
  }
  if (options.balance != Balance::count && options.balance != Balance::width) {
    throw UsageError("--balance: not one of count, width");
  }
  if (!std::isfinite(e.cell_size) || e.cell_size < 0) {
    throw UsageError("--cell-size: must be a finite length >= 0 (0: chosen by cell_choice)");
  }
  if (e.threads < 0) throw UsageError("--threads: must be >= 0 (0: all hardware threads)");
  if (options.max_sample < 1) throw UsageError("max_sample: must be >= 1");
  if (options.max_message_bytes < 64) throw UsageError("max_message_bytes: must be >= 64");
  if (options.resident_steps < 0) throw UsageError("--steps: must be >= 0");
  if (options.memory_limit && options.resident_steps > 0)
    throw UsageError(
        "--memory-limit: not with --steps (the resident steps hold every body's contacts at once)");
  if (!std::isfinite(options.step_motion.spin)) throw UsageError("--spin: must be a finite angle (radians)");
  if (!std::isfinite(options.step_motion.drift)) throw UsageError("--drift: must be a finite length");
  if (!options.final_scene.empty() && options.resident_steps == 0)
    throw UsageError("--final-scene: only with --steps N (the last step's bodies)");
}

namespace {

// ---- the stages of a distributed run ---------------------------------------------------------------

// Rank r's partition of the scene: rows [part_first, part_first + part_count) = [N·r/P, N·(r+1)/P),
// read alone (own rows) or with every other row (every row: rows [0, N)); its bounds.
struct Partition {
  std::uint64_t bodies = 0;  // N
  std::uint64_t first = 0;   // row of position[0]
  std::uint64_t part_first = 0, part_count = 0;
  HostVector<Vec3<double>> position;
  HostVector<double> radius;  // the bounding radius
  ShapeRows shapes;           // the scene has ellipsoids: every row's shape rows; else empty
  bool has_shapes = false;    // the scene has ellipsoids (every rank agrees)
  std::uint64_t ellipsoids = 0;
  Bounds bounds;  // of the partition's rows (count 0: none)
};

Partition read_partition(const Session& session, const std::string& path, bool all_rows) {
  Partition in;
  agreed_stage(session, "read", [&] {
    const SceneShape shape = read_scene_shape(path);
    if (shape.spheres + shape.ellipsoids == 0) throw InputError(path + ": the scene has no bodies");
    in.has_shapes = shape.ellipsoids > 0;
    in.ellipsoids = shape.ellipsoids;
    const std::uint64_t n = shape.spheres + shape.ellipsoids, me = static_cast<std::uint64_t>(session.rank()),
                        p = static_cast<std::uint64_t>(session.size());
    in.bodies = n;
    in.part_first = n * me / p;
    in.part_count = n * (me + 1) / p - in.part_first;
    in.first = all_rows ? 0 : in.part_first;
    const std::uint64_t count = all_rows ? n : in.part_count;
    if (count > 0) {
      BodyRows rows = body_rows(read_scene_rows(path, in.first, count), in.has_shapes);
      if (rows.position.size() != count || rows.radius.size() != count) {
        throw InputError(path + ": rows " + std::to_string(in.first) + "+" + std::to_string(count) +
                         ": read " + std::to_string(rows.radius.size()) + " rows");
      }
      in.position = std::move(rows.position);
      in.radius = std::move(rows.radius);
      in.shapes.shape = std::move(rows.shape);
      in.shapes.semi_axes = std::move(rows.semi_axes);
      in.shapes.orientation = std::move(rows.orientation);
    }
    if (in.part_count > 0) {
      // Bounds (and validation) without an id array: the reader has validated every row already, so
      // compute_bounds finds nothing; if it ever does, it runs again with the global ids, for its message.
      const std::span<const Vec3<double>> pos(in.position.data() + (in.part_first - in.first), in.part_count);
      const std::span<const double> rad(in.radius.data() + (in.part_first - in.first), in.part_count);
      try {
        in.bounds = compute_bounds(BodiesView{pos, rad, {}, {}});
      } catch (const InputError&) {
        std::vector<std::int64_t> id(in.part_count);
        std::iota(id.begin(), id.end(), static_cast<std::int64_t>(in.part_first));
        in.bounds = compute_bounds(BodiesView{pos, rad, id, {}});
      }
    }
  });
  return in;
}

// The read stage: the options checked before any communication, this rank's partition read, the global
// bounds all-gathered (every rank the same: what --precision auto chooses from), and its time.
struct ReadScene {
  Partition part;
  Bounds global;
  bool all_rows = false;
  double seconds = 0;
};

ReadScene read_scene(const Session& session, const std::string& path, const DistributedOptions& options) {
  agreed_stage(session, "options", [&] {
    check_options(options);
    if (path.empty()) throw UsageError("no scene file given");
  });
  const auto t0 = WallClock::now();
  const int ranks = session.size();
  ReadScene in;
  // All rows when the ranks share one node (one page cache). One rank's own rows are all rows: the
  // two modes coincide, and all rows takes the rows as read (no records routed to itself).
  in.all_rows = ranks == 1 || options.read == SceneRead::all_rows ||
                (options.read == SceneRead::automatic && session.local_size() == ranks);
  in.part = read_partition(session, path, in.all_rows);
  fault_point("read", session.rank());
  in.global = allgather_bounds(session, in.part.bounds);
  in.seconds = seconds_since(t0);
  return in;
}

// The frame every rank shares: make_frame of the global bounds, the slab axis, the ghost rule (each
// body's ghost width from its radius: GhostRule), the uniform ghost width of the resident steps
// (2·r_max + the rounding margin of Real) and the broad phase (`auto`: chosen once, from the global
// bounds, for every rank's engine).
struct SharedFrame {
  Bounds global;
  Frame frame;
  int axis = 0;
  GhostRule ghosts;
  double width = 0;
  BroadPhase broad = BroadPhase::grid;
};

template <class Real>
SharedFrame agree_frame(const Session& session, const std::string& path, const Bounds& global,
                        const DistributedOptions& options) {
  const Precision precision = options.engine.fp32_broad_phase ? Precision::mixed : precision_of<Real>();
  SharedFrame f;
  f.global = global;
  agreed_stage(session, "frame", [&] {
    try {
      f.frame = make_frame(f.global, options.engine.cell_size, precision, options.engine.cell_choice);
    } catch (const InputError& e) {  // the scene cannot be run in this mode: name it
      throw InputError(path + ": " + e.what());
    }
    f.axis = choose_axis(f.global, static_cast<int>(options.axis));
    f.width = frame_ghost_width(f.global, f.frame.origin, std::numeric_limits<Real>::epsilon());
    f.ghosts =
        ghost_rule(f.global, frame_extent(f.global, f.frame.origin), std::numeric_limits<Real>::epsilon());
    f.broad = resolved_broad_phase(options.engine.broad_phase, f.global, precision, options.engine.backend,
                                   options.engine.skin != 0);
  });
  return f;
}

// The slab cuts, identical on all ranks: balance count, the quantiles of a regular sample of centre
// coordinates (every stride-th global row, all of them when N <= max_sample) gathered to every rank;
// balance width, equal widths over the global bounds. One rank has no cut, so it samples nothing.
SlabDecomposition make_slabs(const Session& session, const Partition& part, const SharedFrame& f,
                             const DistributedOptions& options) {
  const int ranks = session.size(), axis = f.axis;
  const bool by_count = options.balance == Balance::count;
  std::vector<double> sample;
  if (by_count && ranks > 1) {
    const std::uint64_t stride =
        std::max<std::uint64_t>(1, (part.bodies + options.max_sample - 1) / options.max_sample);
    for (std::uint64_t g = part.part_first + (stride - part.part_first % stride) % stride;
         g < part.part_first + part.part_count; g += stride) {
      sample.push_back(component(part.position[static_cast<std::size_t>(g - part.first)], axis));
    }
    sample = allgather_values(session, sample);
  }
  std::optional<SlabDecomposition> slabs;
  agreed_stage(session, "redistribute", [&] {
    slabs = by_count ? SlabDecomposition::from_sample(axis, std::move(sample), ranks)
                     : SlabDecomposition::equal_width(axis, component(f.global.lo, axis),
                                                      component(f.global.hi, axis), ranks);
  });
  return *slabs;
}

// The bodies a rank holds as the stages go: its owned records (own rows, after distribute), its
// ghosts (after the halo exchange), then the engine's input (every row: straight from the rows).
struct HeldBodies {
  HostVector<BodyRecord> owned;
  Imports<BodyRecord> ghosts;
  HostVector<ShapeRecord> owned_shapes;  // parallel to owned / ghosts when the scene has ellipsoids
  Imports<ShapeRecord> ghost_shapes;
  bool has_shapes = false;
  EngineInput input;
};

// Every body to its owner. Every row: each rank selects its owned bodies and its ghosts from all
// rows (no body moves); own rows: the rows routed to their owners (count → scan → fill) and sent.
HeldBodies distribute(const Session& session, Partition&& part, const SlabDecomposition& slabs,
                      const SharedFrame& f, bool all_rows, int threads) {
  HeldBodies held;
  held.has_shapes = part.has_shapes;
  Exports<BodyRecord> exports;
  Exports<ShapeRecord> shape_exports;
  agreed_stage(session, "redistribute", [&] {
    if (all_rows) {
      held.input = select_owned_and_ghosts(std::move(part.position), std::move(part.radius), slabs, f.ghosts,
                                           session.rank(), threads, std::move(part.shapes));
      return;
    }
    const auto& position = part.position;
    const auto& radius = part.radius;
    const std::uint64_t first = part.first;
    exports = route<BodyRecord>(
        position.size(), session.size(), threads,
        to_owner(slabs, [&](std::size_t i) { return component(position[i], f.axis); }), [&](std::size_t i) {
          return BodyRecord{position[i], radius[i], static_cast<std::int64_t>(first + i)};
        });
    if (part.has_shapes) {  // the same rule, so the same order as the BodyRecords
      const ShapeRows& s = part.shapes;
      shape_exports = route<ShapeRecord>(
          position.size(), session.size(), threads,
          to_owner(slabs, [&](std::size_t i) { return component(position[i], f.axis); }), [&](std::size_t i) {
            return ShapeRecord{s.orientation[i], s.semi_axes[i], s.shape[i]};
          });
    }
  });
  part.position = {};
  part.radius = {};
  part.shapes = {};
  if (!all_rows) {
    held.owned = distribute_to_owners(session, std::move(exports));
    if (held.has_shapes) held.owned_shapes = distribute_to_owners(session, std::move(shape_exports));
  }
  return held;
}

// Ghosts to every rank whose slab is within the body's ghost width (f.ghosts; own rows: every row has
// them already).
void exchange_ghosts(const Session& session, HeldBodies& held, const SlabDecomposition& slabs,
                     const SharedFrame& f, bool all_rows, int threads) {
  if (all_rows) return;
  Exports<BodyRecord> exports;
  Exports<ShapeRecord> shape_exports;
  agreed_stage(session, "halo", [&] {
    const auto& owned = held.owned;
    auto x = [&](std::size_t i) { return component(owned[i].position, f.axis); };
    auto width = [&](std::size_t i) { return f.ghosts.width(owned[i].radius); };
    check_halo_rows(slabs, session.rank(), owned.size(), x, f.ghosts.max_width(f.global.r_max), threads);
    exports = route<BodyRecord>(owned.size(), session.size(), threads, to_ghost_ranks_by(slabs, x, width),
                                [&](std::size_t i) { return owned[i]; });
    if (held.has_shapes) {  // the same rule, so the same order as the BodyRecords
      const auto& shapes = held.owned_shapes;
      shape_exports =
          route<ShapeRecord>(owned.size(), session.size(), threads, to_ghost_ranks_by(slabs, x, width),
                             [&](std::size_t i) { return shapes[i]; });
    }
  });
  held.ghosts = exchange_with_ghost_ranks(session, exports);
  if (held.has_shapes) held.ghost_shapes = exchange_with_ghost_ranks(session, shape_exports);
}

// Owned + ghosts in id order (own rows: merged by id), then the engine with the shared frame; the
// owner of a pair's anchor reports it (the smaller id, or the narrow body of a wide and a narrow one:
// bodies.hpp). A rank that owns nothing reports nothing. With a memory limit the engine runs in pieces
// (decomposition/pieces.hpp); given a `stream`, each piece's rows are appended to the output file as
// they come (one rank: the pieces are the file's rows in order) and nothing is returned.
template <class Real>
Contacts<Real> detect_local(const Session& session, Engine<Real>& engine, HeldBodies& held,
                            const SharedFrame& f, bool full, int threads, std::uint64_t memory_limit,
                            const std::function<void(const std::string&)>& log, PieceReport& report,
                            ContactFileStream* stream) {
  Contacts<Real> local;
  local.full = full;
  agreed_stage(session, "detect", [&] {
    if (held.input.position.empty()) {  // own rows (every row: selected by distribute)
      held.input = merge_by_id(held.owned, held.ghosts.rows, held.ghosts.counts, threads, held.owned_shapes,
                               held.ghost_shapes.rows, f.ghosts);
    }
    held.owned = {};
    held.ghosts = {};
    held.owned_shapes = {};
    held.ghost_shapes = {};
    if (held.input.owned > 0) {
      PieceOptions pieces;
      pieces.memory_limit = memory_limit;
      pieces.log = log;
      const int rank = session.rank();
      pieces.before_piece = [rank](std::uint64_t piece) {  // a signal stops the run between pieces
        stop_point();
        if (piece == 1) fault_point("piece", rank);
      };
      if (stream) {
        detect_in_pieces<Real>(
            engine, held.input.view(), f.frame, pieces,
            [stream, threads](Contacts<Real>&& rows) { stream->append(rows, threads); }, &report);
      } else {
        local = detect_in_pieces(engine, held.input.view(), f.frame, pieces, &report);
      }
    }
  });
  return local;
}

// The contacts of every rank: gathered to rank 0 or exchanged by id_a range, then merged.
template <class Real>
CollectedContacts<Real> collect_contacts(const Session& session, Contacts<Real>&& local, std::uint64_t bodies,
                                         const DistributedOptions& options, int threads) {
  CollectOptions o;
  o.max_message_bytes = options.max_message_bytes;
  o.threads = threads;
  o.log = options.log;
  return options.output == ContactOutput::gather ? gather_contacts(session, std::move(local), bodies, o)
                                                 : exchange_contacts(session, std::move(local), bodies, o);
}

// The engine of the run's mode, built with the rank's threads (after the read: --precision auto
// chooses the mode from the agreed bounds).
template <class Real>
std::optional<Engine<Real>> make_engine(const Session& session, const DistributedOptions& options,
                                        int threads, BroadPhase broad) {
  std::optional<Engine<Real>> engine;
  agreed_stage(session, "engine", [&] {
    EngineOptions engine_options = options.engine;
    engine_options.threads = threads;
    engine_options.broad_phase = broad;
    if (options.memory_limit) engine_options.device_memory_limit = options.memory_limit;
    engine.emplace(engine_options);
  });
  return engine;
}

// The run's statistics after detection: the engine's counts summed over ranks, the balance of the
// slabs (owned bodies per rank) and the ghosts held. Collective.
template <class Real>
void record_detection(const Session& session, const Engine<Real>& engine, const EngineInput& input,
                      const PieceReport& pieces, DistributedResult<Real>& result) {
  result.backend = engine.backend();
  if (input.owned > 0) result.stats = pieces.stats;  // (one piece: the engine's)
  result.stats.entries = session.sum(result.stats.entries);
  result.stats.pair_tests = session.sum(result.stats.pair_tests);
  result.stats.narrow_fallbacks = session.sum(result.stats.narrow_fallbacks);
  result.stats.narrow_unconverged = session.sum(result.stats.narrow_unconverged);
  result.stats.narrow_unsettled = session.sum(result.stats.narrow_unsettled);
  result.stats.narrow_hard = session.sum(result.stats.narrow_hard);
  result.stats.narrow_solver_runs = session.sum(result.stats.narrow_solver_runs);
  result.stats.narrow_evaluations = session.sum(result.stats.narrow_evaluations);
  result.stats.narrow_max_evaluations =
      std::uint64_t(session.max(double(result.stats.narrow_max_evaluations)));
  result.stats.fp64_rows = session.sum(result.stats.fp64_rows);
  result.stats.ellipsoids = result.ellipsoids;  // the scene's (the engines' counts include ghosts)
  result.stats.key_bits = int(session.max(double(result.stats.key_bits)));
  result.stats.levels = int(session.max(double(result.stats.levels)));
  const std::vector<std::uint64_t> owned = allgather_counts(session, input.owned);
  result.owned_min = *std::min_element(owned.begin(), owned.end());
  result.owned_max = *std::max_element(owned.begin(), owned.end());
  result.ghosts = session.sum(input.ghosts);
}

template <class Real>
void record_contacts(CollectedContacts<Real>&& c, DistributedResult<Real>& result) {
  result.contacts = std::move(c.contacts);
  result.first_row = c.first_row;
  result.total_contacts = c.total_contacts;
  result.id_begin = c.id_begin;
  result.id_end = c.id_end;
  result.duplicates_removed = c.duplicates_removed;
}

// The stages frame … collect after the read stage (read_scene), with their times (max over ranks)
// and the run's statistics. Called inside the rank's DefaultTeam of `threads`.
template <class Real>
DistributedResult<Real> distributed_run(Session& session, const std::string& path,
                                        const DistributedOptions& options, ReadScene&& in, int threads,
                                        ContactFileStream* stream = nullptr) {
  const bool all_rows = in.all_rows;
  Partition& part = in.part;
  DistributedResult<Real> result;
  result.ranks = session.size();
  result.threads = threads;
  result.read = all_rows ? SceneRead::all_rows : SceneRead::own_rows;
  StageClock clock;
  clock.add(RunStage::read, in.seconds);

  clock.start();
  const SharedFrame f = agree_frame<Real>(session, path, in.global, options);
  check_drift_range<Real>(session, path, f.global, options);
  clock.stop(RunStage::read);
  std::optional<Engine<Real>> engine = make_engine<Real>(session, options, threads, f.broad);
  result.bodies = part.bodies;
  result.ellipsoids = part.ellipsoids;
  result.frame = f.frame;
  result.cell_size = f.frame.cell_size;
  result.axis = f.axis;

  stop_point();
  clock.start();
  fault_point("exchange", session.rank());
  const SlabDecomposition slabs = make_slabs(session, part, f, options);
  HeldBodies held = distribute(session, std::move(part), slabs, f, all_rows, threads);
  clock.stop(RunStage::redistribute);
  result.cuts = slabs.cuts();

  clock.start();
  exchange_ghosts(session, held, slabs, f, all_rows, threads);
  clock.stop(RunStage::halo);

  stop_point();
  clock.start();
  fault_point("detect", session.rank());
  PieceReport pieces;
  Contacts<Real> local = detect_local(session, *engine, held, f, options.engine.fields == Fields::full,
                                      threads, options.memory_limit, options.log, pieces, stream);
  clock.stop(RunStage::detect);
  if (held.input.owned > 0) clock.add_engine(pieces.times);  // (in pieces: summed over them)
  record_detection(session, *engine, held.input, pieces, result);
  result.memory_limit = options.memory_limit;
  result.pieces = std::uint64_t(session.max(double(pieces.pieces)));
  result.piece_detections = std::uint64_t(session.max(double(pieces.attempts)));
  if (options.resident_steps == 0) held.input = {};  // else the steps start from it

  stop_point();
  fault_point("gather", session.rank());
  if (stream) {  // the rows are in the output file already
    result.total_contacts = stream->rows();
    result.times = clock.times(session, RunStage::gather);
    return result;
  }
  CollectedContacts<Real> c = collect_contacts(session, std::move(local), result.bodies, options, threads);
  const RunStage transfer = options.output == ContactOutput::gather ? RunStage::gather : RunStage::exchange;
  clock.add(transfer, c.transfer_seconds);
  clock.add(RunStage::merge, c.merge_seconds);
  record_contacts(std::move(c), result);

  if (options.resident_steps > 0) {
    std::optional<Contacts<Real>> last;  // --drift: the last step's contacts become the run's
    result.steps = run_steps(session, *engine, slabs, held.input, result, options, threads, last);
    if (last)
      record_contacts(collect_contacts(session, std::move(*last), result.bodies, options, threads), result);
  }
  result.times = clock.times(session, transfer);
  return result;
}

// A pair stage far above the usual (pair_work_unusual) is said once per process, on any rank, before
// it runs: a run that would take hours says so instead of running without a word.
void warn_unusual_pair_work(const PairEstimate& e, const std::string& prefix) {
  static std::atomic<bool> said{false};
  if (!pair_work_unusual(e) || said.exchange(true)) return;
  fmt::print(
      stderr,
      "contactgrid: warning: {}the pair stage will make {}, far more than usual (a few to a few hundred "
      "per body): expect a long run; --max-pair-tests N refuses such scenes\n",
      prefix, describe(e));
  std::fflush(stderr);
}

DistributedOptions run_options(const DetectCommand& cmd, const Session& session) {
  DistributedOptions o;
  o.engine.backend = cmd.backend;
  o.engine.fields = cmd.fields;
  o.engine.cell_size = cmd.cell_size;
  o.engine.cell_choice = cmd.cell_choice;
  o.engine.broad_phase = cmd.broad_phase;
  o.engine.threads = cmd.threads;
  o.engine.ellipsoid_tolerance = cmd.solver_tolerance;
  o.engine.ellipsoid_max_iterations = cmd.solver_iterations;
  o.engine.skin = cmd.skin;
  o.engine.max_pair_tests = cmd.max_pair_tests;
  o.memory_limit = cmd.memory_limit;
  // A pair stage far above the usual is said before it runs (any rank) and, on rank 0's terminal,
  // shows its progress in pair tests (run/progress.hpp; both backends report it).
  auto pair_bar = std::make_shared<std::unique_ptr<Progress>>();
  o.engine.on_pair_estimate = [pair_bar, draw = !cmd.quiet && session.rank() == 0,
                               prefix = session.uses_mpi() ? session.prefix()
                                                           : std::string()](const PairEstimate& e) {
    warn_unusual_pair_work(e, prefix);
    if (pair_work_unusual(e))
      *pair_bar = std::make_unique<Progress>("detect: pair stage", "pair tests", e.tests, draw);
  };
  o.engine.on_pair_progress = [pair_bar](std::uint64_t done, bool finished) {
    if (!*pair_bar) return;
    (*pair_bar)->update(done);
    if (finished) pair_bar->reset();
  };
  if (cmd.backend != Backend::cpu) o.engine.device = session.device_for(cuda_device_count());
  o.axis = cmd.axis;
  o.balance = cmd.balance;
  o.read = cmd.read;
  // The merge line says how many runs were merged: something only under mpirun.
  if (cmd.verbose && !cmd.quiet && session.rank() == 0 && session.size() > 1)
    o.log = [](const std::string& line) { fmt::print("{}\n", line); };
  // The design card's shape by default: rank 0 gathers, deduplicates and writes the sorted contacts
  // (--write gather). --write ranks: each rank keeps the contacts of its id_a range and writes them
  // into the one output file. A CSV copy is written by rank 0 alone, so it always gathers.
  o.output = cmd.csv.empty() ? cmd.write : ContactOutput::gather;
  o.resident_steps = cmd.steps;
  o.step_motion.spin = cmd.spin;
  o.step_motion.drift = cmd.drift;
  o.engine.skin_auto = cmd.skin_auto;
  o.final_scene = cmd.final_scene;
  if (cmd.steps > 0) {  // a progress line on rank 0's terminal (run/progress.hpp)
    auto bar = std::make_shared<Progress>("detect: resident steps", "steps", std::uint64_t(cmd.steps),
                                          !cmd.quiet && session.rank() == 0);
    o.step_motion.on_step = [bar, steps = cmd.steps](int done) {
      bar->update(std::uint64_t(done));
      if (done == steps) bar->finish();
    };
  }
  return o;
}

// The output file's record of the run (its root attributes): what ran, on what, and the stage times.
template <class Real>
void describe_run(const DistributedResult<Real>& r, const DetectCommand& cmd, RunInfo& info) {
  info.bodies = r.bodies;
  info.backend = to_string(r.backend);
  info.ranks = r.ranks;
  info.cell_size = r.cell_size;
  info.input = cmd.input;
  info.times = file_stage_times(r.times);
  info.ellipsoids = r.ellipsoids;
  info.narrow_fallbacks = r.stats.narrow_fallbacks;
  info.narrow_unconverged = r.stats.narrow_unconverged;
}

// Every rank writes its rows of the one file (src/run/contact_file_shared.hpp); the file records the
// times so far and the write's. Returns the write's time.
template <class Real>
RunTime write_output(Session& session, const DetectCommand& cmd, const DistributedResult<Real>& r,
                     RunInfo& info) {
  describe_run(r, cmd, info);
  const double seconds = write_contacts_distributed(session, cmd.output, r.contacts, r.first_row,
                                                    r.total_contacts, info, r.threads);
  return {RunStage::write, -1, seconds};
}

// The streamed output file's root attributes and its rename (its rows were appended as the pieces
// came). Returns the time of this last step.
template <class Real>
RunTime commit_stream(ContactFileStream& stream, const DistributedResult<Real>& r, const DetectCommand& cmd,
                      RunInfo& info) {
  const auto t0 = WallClock::now();
  describe_run(r, cmd, info);
  info.times.push_back({"write", seconds_since(t0)});
  stream.commit(info);
  return {RunStage::write, -1, seconds_since(t0)};
}

// The CSV copy, by rank 0 (which holds every contact: --csv gathers). Returns its time (rank 0).
template <class Real>
RunTime write_csv(const Session& session, const std::string& path, const Contacts<Real>& contacts) {
  std::exception_ptr error;
  double seconds = 0;
  if (session.rank() == 0) {
    try {
      auto t = WallClock::now();
      write_contacts_csv(path, contacts);
      seconds = seconds_since(t);
    } catch (...) {
      error = std::current_exception();
    }
  }
  session.agree(error, "csv");
  return {RunStage::csv, -1, seconds};
}

// A failing MPI call (CommFailure) leaves other ranks possibly waiting in a collective this rank will
// never join: it ends the job (Session::abort, exit code 5), its registered temporaries removed first.
template <class F>
auto or_abort(Session& session, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const CommFailure& e) {
    run_cleanup_actions();
    session.abort(e.exit_code(), e.what());
  }
}

// The mode of the run: --precision as given, or (auto) choose_precision on the agreed global bounds
// and the backend every rank runs (cuda only where every rank's engine would), so every rank picks
// the same mode.
PrecisionChoice choose_mode(const Session& session, const DetectCommand& cmd, const ReadScene& in) {
  if (cmd.precision) return {*cmd.precision, {}};
  const Backend mine =
      cmd.backend == Backend::automatic ? (cuda_available() ? Backend::cuda : Backend::cpu) : cmd.backend;
  const Backend backend = session.max(mine == Backend::cuda ? 0.0 : 1.0) > 0 ? Backend::cpu : Backend::cuda;
  PrecisionChoice pick;
  agreed_stage(session, "frame", [&] {
    try {
      const bool ellipsoids = in.part.has_shapes;
      pick = choose_precision(precision_scene(in.global, ellipsoids, cmd.cell_size, cmd.cell_choice), backend,
                              cmd.accuracy);
    } catch (const InputError& e) {  // no mode meets the accuracy here: name the scene
      throw InputError(cmd.input + ": " + e.what());
    }
  });
  return pick;
}

// frame → slabs → distribute → exchange ghosts → detect → collect contacts (distributed_run) → write →
// summary, in the chosen mode.
template <class Real>
int run_in_mode(const DetectCommand& cmd, Session& session, const DistributedOptions& options, ReadScene&& in,
                const PrecisionChoice& choice, int threads, DeviceWarmUp& warm) {
  // One rank under a memory limit writes the contacts as its pieces come (host memory: a piece or
  // two, never all rows); a CSV copy or several ranks gather them first.
  std::optional<ContactFileStream> stream;
  if (options.memory_limit && session.size() == 1 && cmd.csv.empty() && options.resident_steps == 0)
    stream.emplace(cmd.output, precision_of<Real>(), FieldSet(options.engine.fields == Fields::full));
  // The free blocks the host pool keeps for reuse count against the limit as well.
  if (stream) cap_host_pool(options.memory_limit);
  const double waited = warm.wait();
  DistributedResult<Real> r = or_abort(session, [&] {
    return distributed_run<Real>(session, cmd.input, options, std::move(in), threads,
                                 stream ? &*stream : nullptr);
  });
  r.warm_up = warm.seconds();
  r.warm_up_context = warm.context_seconds();
  r.warm_up_wait = waited;
  RunTimes times = r.times;
  RunInfo info;
  info.precision = to_string(choice.mode);
  info.precision_choice = choice.reason;
  stop_point();
  // The contact file and its CSV copy appear both or neither (rank 0 renames them into place).
  FinishedOutputs outputs;
  if (stream)
    times.push_back(commit_stream(*stream, r, cmd, info));
  else
    times.push_back(write_output(session, cmd, r, info));
  if (session.rank() == 0) outputs.add(cmd.output);
  if (!cmd.csv.empty()) {
    times.push_back(write_csv(session, cmd.csv, r.contacts));
    if (session.rank() == 0) outputs.add(cmd.csv);
  }
  stop_point();
  outputs.keep();
  if (!cmd.quiet && session.rank() == 0) print_summary(info, times, r.total_contacts, r);
  return 0;
}

}  // namespace

template <class Real>
DistributedResult<Real> distributed_detect(Session& session, const std::string& scene_path,
                                           const DistributedOptions& options) {
  return or_abort(session, [&] {
    const int threads = host_threads(options.engine.threads, session);
    const DefaultTeam team(threads);
    return distributed_run<Real>(session, scene_path, options, read_scene(session, scene_path, options),
                                 threads);
  });
}

template DistributedResult<float> distributed_detect<float>(Session&, const std::string&,
                                                            const DistributedOptions&);
template DistributedResult<double> distributed_detect<double>(Session&, const std::string&,
                                                              const DistributedOptions&);

namespace {

// The directory `file` goes into exists and this process may create files there, and `file` is not
// itself a directory; IoError naming `option`, the file and the directory otherwise. Checked before the
// scene is read, so that a mistyped output path fails at once rather than after the whole run.
void require_writable_directory(const std::string& option, const std::string& file) {
  namespace fs = std::filesystem;
  const fs::path parent = fs::path(file).parent_path();
  const std::string dir = parent.empty() ? std::string(".") : parent.string();
  std::error_code ec;
  const fs::file_status status = fs::status(dir, ec);
  auto fail = [&](const std::string& why) {
    throw IoError(fmt::format("{} {}: cannot write into the directory {}: {}", option, file, dir, why));
  };
  if (status.type() == fs::file_type::none) fail(ec.message());  // e.g. a parent not searchable
  if (!fs::exists(status)) fail("it does not exist");
  if (!fs::is_directory(status)) fail("it is not a directory");
  if (::access(dir.c_str(), W_OK | X_OK) != 0) fail(std::strerror(errno));
  if (fs::is_directory(fs::status(file, ec)))
    throw IoError(fmt::format("{} {}: is a directory, not a file name", option, file));
}

// Every rank that writes checks its files' directories: rank 0 the output file and the CSV copy,
// with --write ranks every rank the output file (each writes its rows into it).
void check_output_directories(const Session& session, const DetectCommand& cmd,
                              const DistributedOptions& options) {
  agreed_stage(session, "output", [&] {
    if (session.rank() == 0 || options.output == ContactOutput::ranks)
      require_writable_directory("-o", cmd.output);
    if (session.rank() == 0 && !cmd.csv.empty()) require_writable_directory("--csv", cmd.csv);
  });
}

}  // namespace

// read → (--precision auto: choose the mode) → the run in that mode → write → summary
int run_detect(const DetectCommand& cmd, Session& session) {
  if (cmd.output.empty()) throw UsageError("detect: -o/--output is required");
  if (cmd.precision && cmd.accuracy.position)
    throw UsageError(std::string("--accuracy: only with --precision auto (the default), not --precision ") +
                     to_string(*cmd.precision));
  DistributedOptions options = run_options(cmd, session);
  check_output_directories(session, cmd, options);
  const int threads = host_threads(options.engine.threads, session);
  const DefaultTeam team(threads);
  // The GPU's context and the kernels of a detection in the mode asked (auto: each until chosen) made
  // ready on a thread of their own while the scene is read.
  DeviceWarmUp warm(options.engine,
                    cmd.precision ? DeviceWarmUp::bit(*cmd.precision) : DeviceWarmUp::all_modes());
  ReadScene in = or_abort(session, [&] { return read_scene(session, cmd.input, options); });
  const PrecisionChoice choice = or_abort(session, [&] { return choose_mode(session, cmd, in); });
  warm.keep_only(choice.mode, in.part.has_shapes);
  options.engine.fp32_broad_phase = choice.mode == Precision::mixed;
  return choice.mode == Precision::fp32
             ? run_in_mode<float>(cmd, session, options, std::move(in), choice, threads, warm)
             : run_in_mode<double>(cmd, session, options, std::move(in), choice, threads, warm);
}

}  // namespace cg
