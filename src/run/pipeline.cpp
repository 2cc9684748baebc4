// Sequencing of a contactgrid run. Reads like the data flow; each stage is one call:
//   read → frame → slabs → distribute → exchange ghosts → detect → collect contacts
// (distributed_run.hpp); the `detect` command adds the write and the summary (detect_command.cpp).
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
#include "run/distributed_run.hpp"
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

}  // namespace

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

namespace {

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
                                   keeps_candidates(options.engine));
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

}  // namespace

// The stages frame … collect after the read stage (distributed_run.hpp).
template <class Real>
DistributedResult<Real> distributed_run(Session& session, const std::string& path,
                                        const DistributedOptions& options, ReadScene&& in, int threads,
                                        ContactFileStream* stream) {
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

template DistributedResult<float> distributed_run<float>(Session&, const std::string&,
                                                         const DistributedOptions&, ReadScene&&, int,
                                                         ContactFileStream*);
template DistributedResult<double> distributed_run<double>(Session&, const std::string&,
                                                           const DistributedOptions&, ReadScene&&, int,
                                                           ContactFileStream*);

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

}  // namespace cg
