#pragma once
// Internal to comm/ (the step loop's translation units: resident_steps.cpp, step_halo.cpp,
// step_migrate.cpp): the state of a StepLoop (resident_steps.hpp) and what its stages share.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <numeric>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <utility>

#include "agreed_stage.hpp"
#include "collectives.hpp"
#include "contact_merge.hpp"
#include "resident_steps.hpp"
#include "routing.hpp"
#include "skin_tuner.hpp"
#include "step_plan.hpp"
#include "timing.hpp"
#include "transport.hpp"

namespace cg {
namespace step_detail {

constexpr int k_body_gather_tag = 7600;  // + field index

// Page-locked host memory for an engine's copies (released before the memory is).
template <class Real>
struct Pin {
  Engine<Real>& engine;
  void* p;
  bool pinned;
  Pin(Engine<Real>& e, void* ptr, std::size_t bytes) : engine(e), p(ptr), pinned(e.pin_host(ptr, bytes)) {}
  ~Pin() {
    if (pinned) engine.unpin_host(p);
  }
  Pin(const Pin&) = delete;
  Pin& operator=(const Pin&) = delete;
};

// A boundary row as a step sends it in a scene with ellipsoids: the orientation in the same message
// as the position and bounding radius (64 bytes; a sphere-only scene sends BodyRecords, 40).
struct OrientedRecord {
  Vec3<double> position;
  double radius;
  Quat<double> orientation;
};

// The step loop's own trace (CONTACTGRID_STEP_TRACE=1): each rank writes one stderr line per layout
// and per building step with the seconds of each part, for finding where a rebuild's time goes
// (the stage table sums those parts).
struct Trace {
  bool on = false;
  WallClock::time_point last;
  std::string line;
  void start() {
    if (!on) return;
    line.clear();
    last = WallClock::now();
  }
  void mark(const char* part) {
    if (!on) return;
    char buf[64];
    std::snprintf(buf, sizeof buf, " %s %.4f", part, seconds_since(last));
    line += buf;
    last = WallClock::now();
  }
  void value(const char* part, double seconds) {
    if (!on) return;
    char buf[64];
    std::snprintf(buf, sizeof buf, " %s %.4f", part, seconds);
    line += buf;
  }
  void print(int rank, int layout, const char* what) const {
    if (on) std::fprintf(stderr, "trace rank %d layout %d %s:%s\n", rank, layout, what, line.c_str());
  }
};

}  // namespace step_detail

template <class Real>
struct StepLoop<Real>::State {
  Session& session;
  detail::Comm comm;
  Engine<Real>& a;  // engine A: the owned bodies
  SlabDecomposition slabs;
  StepMotion motion;
  int threads;
  StepBalance balance;
  Bounds global;         // the bodies' bounds over the ranks (update_frame)
  Frame frame;           // the frame of a run from scratch of them
  double width = 0;      // its ghost width
  bool shapes = false;   // the scene has ellipsoids (agreed over the ranks)
  bool refresh = false;  // every step refreshes the ghosts' orientations
  bool grow = false;     // ... and their semi-axes

  // the skin: fixed (EngineOptions::skin) or chosen (skin_auto) at each layout
  bool skin_auto = false;
  double skin = 0;
  SkinTuner tuner;
  // Over several ranks a layout lasts StepMotion::layout_skins skins (its ghost width and the rebuild
  // check's margin): the engines rebuild their lists at their own checks in between, without a
  // migration or a layout (~40 ms of host work a layout at 2^25 bodies a rank); the halo grows by the
  // extra margin. One rank: the layout is the engine's build (factor 1). CONTACTGRID_STEP_LAYOUT_SKIN=k
  // overrides the factor.
  double layout_factor = 1;
  double layout_skin() const { return session.size() > 1 ? layout_factor * skin : skin; }

  StepBodies bodies;  // owned, ascending id
  StepBodies spare;   // the previous rows' storage: the next migration's rows are merged into it
  // a migration changes engine A's rows in place (Engine::splice_resident); CONTACTGRID_STEP_MIGRATE=
  // whole: the layout sets them all again (set_resident), the former path
  bool splice = true;
  bool rows_changed = true;  // bodies' rows (ids) differ from engine A's: the layout sets them
  bool uploaded = false;     // this step's layout set engine A's rows from the moved bodies
  bool written = false;      // this step's update_frame wrote the moved positions into engine A
  StepPlan plan;             // of the owned rows: interior or boundary, and the halo
  GhostRule rule;            // the layout's halo rule (StepMotion::ghosts_by_radius; else uniform)
  BoundaryRows rows;         // engine B's row of each boundary row and each ghost
  std::vector<std::uint64_t> send_counts, recv_counts;
  std::vector<double> axis_coordinate;  // the owned centres along the slab axis (coordinates())
  int steps_since_layout = 0;
  double displacement = 0;  // the largest since the layout (rebuild_due; max over ranks)
  double moved = 0;         // ... this rank's (update_frame: engine A's resident_extent)
  int layouts = 0;
  std::uint64_t migrated = 0, rebalances = 0;
  // engine B's rows, host side: storage kept across layouts (grown with room to spare), page-locked
  // while it stays where it is
  HostVector<Vec3<double>> b_p;
  HostVector<double> b_r;
  HostVector<std::int64_t> b_id;
  HostVector<std::uint8_t> b_mask;
  HostVector<Shape> b_shape;        // scenes with ellipsoids
  HostVector<Vec3<double>> b_semi;  // (refreshed every step when the semi-axes travel)
  HostVector<Quat<double>> b_q;     // (refreshed every step)
  std::optional<Engine<Real>> b;    // engine B, made at the first layout with boundary rows
  bool b_active = false;            // this layout has boundary rows
  std::optional<step_detail::Pin<Real>> pin_p, pin_r, pin_q, pin_semi;
  // The halo where the rows are (the default): the rows' lists kept in the engines from the layout
  // (A: the halo's rows in the order they are sent, and the boundary rows; B: the ghosts' rows in the
  // order they arrive, and the boundary rows), each step's rows gathered from A into its page-locked
  // buffer, exchanged, and scattered into B, B's boundary rows copied from A where they are.
  // CONTACTGRID_STEP_HALO=host, or semi-axes that travel (StepMotion::send_semi_axes): the host's
  // records from the bodies, B's rows all written again (the former path).
  bool device_halo = true;  // the knob
  // The rows that may have left their slab (migrate) or lie near its cuts (lay_out's plan) listed
  // where engine A's rows are (Engine::rows_outside), the host testing those alone;
  // CONTACTGRID_STEP_SCAN=host: the host's pass over every row (the former path).
  bool device_scan = true;
  // A migration's merge of the host rows (every body's ~96 bytes copied into the spare storage) runs on
  // a thread of its own beside the step's detection, where the host waits for the device, and is
  // joined where the rows are read whole (finish_merge: bodies(), update_frame, …; it runs there if it
  // has not started); until then the layout reads the few rows it needs through `merged` (the previous
  // rows and the arrivals, in place). Beside the layout instead, the merge's memory traffic and threads
  // slowed every loop of the layout (CONTACTGRID_STEP_MERGE=layout); CONTACTGRID_STEP_MERGE=wait: the
  // merge before the layout. Only with the scans where the rows are (device_scan) and engine A's rows
  // spliced in place.
  bool defer_merge = true;
  bool merge_at_detection = true;
  // Beside the layout, the merge's thread and the layout's loops share the rank's threads (half each),
  // so that two OpenMP teams of the whole share do not oversubscribe the rank's cores (their barriers
  // spin on descheduled threads). CONTACTGRID_STEP_MERGE_TEAM=whole: each takes the whole share.
  bool split_team = true;
  // Engine B (the boundary) runs at the device's highest priority (EngineOptions::high_priority): its
  // ghosts' scatter and its detection are few blocks, which at one priority wait on the GPU until the
  // interior detection of engine A has issued all of its blocks. CONTACTGRID_STEP_PRIORITY=same: both
  // at the default priority.
  bool boundary_first = true;
  int merge_threads() const { return split_team && !merge_at_detection ? std::max(1, threads / 2) : threads; }
  // The threads of a loop that may run beside the merge.
  int team() const { return merge_started && split_team ? std::max(1, threads - threads / 2) : threads; }
  std::thread merging;
  bool merge_pending = false;                     // a migration's rows are still to be merged
  bool merge_started = false;                     // ... on the thread `merging`
  std::vector<std::size_t> merge_gone, merge_at;  // splice_step_bodies' leaving rows and arrival places
  bool merge_shapes = false;
  std::exception_ptr merge_error;
  SpliceMap merged;                     // the new rows' sources while the merge runs
  StepBodies arrivals;                  // this migration's arrivals (ascending id)
  bool halo_lists = false;              // this layout set the lists (the halo where the rows are)
  std::span<const std::byte> gathered;  // this step's halo rows, packed (engine A's buffer)
  HostVector<std::byte> halo_spare;     // the rows received without an engine B, or sent after an error
  std::uint64_t halo_rows = 0;          // ghosts received per step
  double setup = 0;
  std::uint64_t builds0 = 0, reuses0 = 0;  // engine A's counters before the steps
  step_detail::Trace trace;                // CONTACTGRID_STEP_TRACE=1

  // the step in flight
  std::thread interior;
  std::exception_ptr error, interior_error;
  WallClock::time_point s0;
  std::uint64_t found_a = 0, found_b = 0;
  std::array<double, kStepStageCount> t{};
  std::uint64_t builds_before = 0;
  double tuner_displacement = 0;
  int tuner_steps = 0;

  // every step's
  std::vector<std::array<double, kStepStageCount>> times;
  std::vector<std::vector<double>> engine_times;  // engine A's stages, by engine_stage_names()
  std::vector<std::uint64_t> found;               // this rank's contacts
  std::vector<std::uint64_t> hashes;              // this rank's contacts_hash (hash_every_step)
  std::vector<double> built;                      // 1: engine A built its candidates this step
  std::vector<double> relaid;                     // 1: the step rebuilt the rows (lay_out)
  bool relaid_now = false;

  State(Session& s, Engine<Real>& e, const SlabDecomposition& sl, const StepMotion& m, int th,
        const StepBalance& bal)
      : session(s), comm(s), a(e), slabs(sl), motion(m), threads(th), balance(bal) {
    skin_auto = e.options().skin_auto;
    skin = skin_auto ? 0 : e.options().skin;
    builds0 = e.stats().candidate_builds;
    reuses0 = e.stats().candidate_reuses;
    const char* knob = std::getenv("CONTACTGRID_STEP_MIGRATE");
    splice = !(knob && std::string(knob) == "whole");
    const char* halo_knob = std::getenv("CONTACTGRID_STEP_HALO");
    device_halo = !(halo_knob && std::string(halo_knob) == "host");
    const char* scan_knob = std::getenv("CONTACTGRID_STEP_SCAN");
    device_scan = !(scan_knob && std::string(scan_knob) == "host");
    const char* merge_knob = std::getenv("CONTACTGRID_STEP_MERGE");
    defer_merge = !(merge_knob && std::string(merge_knob) == "wait");
    merge_at_detection = !(merge_knob && std::string(merge_knob) == "layout");
    const char* team_knob = std::getenv("CONTACTGRID_STEP_MERGE_TEAM");
    split_team = !(team_knob && std::string(team_knob) == "whole");
    const char* priority_knob = std::getenv("CONTACTGRID_STEP_PRIORITY");
    boundary_first = !(priority_knob && std::string(priority_knob) == "same");
    layout_factor = m.layout_skins;
    if (const char* k = std::getenv("CONTACTGRID_STEP_LAYOUT_SKIN")) layout_factor = std::strtod(k, nullptr);
    if (!(layout_factor >= 1) || !std::isfinite(layout_factor))
      throw UsageError("steps: a layout's skins (StepMotion::layout_skins, CONTACTGRID_STEP_LAYOUT_SKIN) " +
                       std::to_string(layout_factor) + " is not a number >= 1");
    const char* trace_knob = std::getenv("CONTACTGRID_STEP_TRACE");
    trace.on = trace_knob && std::string(trace_knob) == "1";
  }
  ~State() {
    if (interior.joinable()) interior.join();
    if (merging.joinable()) merging.join();
  }

  // The migration's merge on its own thread (once; nothing when none is pending). Beside a detection
  // on the CPU, whose team takes the rank's threads, it runs here instead, before the detection.
  void start_merge() {
    if (!merge_pending || merge_started) return;
    if (merge_at_detection && a.backend() == Backend::cpu) {
      finish_merge();
      return;
    }
    merging = std::thread([this] { run_merge(merge_threads()); });
    merge_started = true;
  }
  // The merge itself: the rows that stay and the arrivals into the spare storage (an error kept for
  // finish_merge to throw).
  void run_merge(int team_size) {
    try {
      splice_step_bodies(bodies, merge_gone, merge_at, arrivals, merge_shapes, spare, team_size);
    } catch (...) {
      merge_error = std::current_exception();
    }
  }
  // The migration's merge finished (run here when it has not started): its rows are the bodies (the
  // previous ones the spare).
  void finish_merge() {
    if (!merge_pending) return;
    const auto w0 = WallClock::now();
    if (merge_started)
      merging.join();
    else
      run_merge(threads);
    t[static_cast<std::size_t>(StepStage::merge_wait)] += seconds_since(w0);
    merge_pending = merge_started = false;
    std::swap(bodies, spare);
    if (merge_error) std::rethrow_exception(std::exchange(merge_error, nullptr));
  }
  // Body i after the migration: the rows to read and its row there (while the merge runs, the
  // previous rows or the arrivals).
  std::pair<const StepBodies*, std::size_t> body(std::size_t i) const {
    if (!merge_pending) return {&bodies, i};
    const SpliceMap::Source src = merged(i);
    return {src.arrival ? &arrivals : &bodies, src.row};
  }
  std::size_t held() const { return merge_pending ? merged.size() : bodies.size(); }

  void fail() {
    if (!error) error = std::current_exception();
  }

  // The owned centres along the slab axis (a buffer kept across rebuilds).
  std::span<const double> coordinates() {
    finish_merge();
    const std::size_t n = bodies.size();
    axis_coordinate.resize(n);
    const Vec3<double>* x = bodies.position.data();
    double* c = axis_coordinate.data();
    const int axis = slabs.axis();
#pragma omp parallel for num_threads(threads) schedule(static) if (n > (std::size_t(1) << 15))
    for (std::size_t k = 0; k < n; ++k) c[k] = component(x[k], axis);
    return axis_coordinate;
  }

  // `v` resized to n rows; grown storage (room for a quarter more) moves, so its page lock `pin`
  // (when given: the rows a step writes) is released first and taken again on the new storage.
  template <class T>
  void resize_kept(HostVector<T>& v, std::size_t n, std::optional<step_detail::Pin<Real>>* pin) {
    if (n > v.capacity()) {
      if (pin) pin->reset();
      HostVector<T> grown;
      grown.reserve(n + n / 4);
      v.swap(grown);
    }
    v.resize(n);
    if (pin && !*pin && v.capacity() > 0) pin->emplace(a, v.data(), v.capacity() * sizeof(T));
  }

  // Engine B's rows from the bodies' boundary rows and the ghosts' records (the layout's exchange).
  void make_engine_b(const HostVector<BodyRecord>& ghosts, const HostVector<ShapeRecord>& ghost_shapes);

  // The engines' row lists of the halo where the rows are (Engine::set_row_list): A's rows sent
  // (grouped by destination, as plan.halo) and B's ghost rows (in the order they arrive); both
  // engines' boundary rows (plan.boundary, rows.of_boundary).
  static constexpr int kHaloList = 0, kBoundaryList = 1;
  // step_halo.cpp: this step's halo rows gathered from engine A and B's boundary rows copied from
  // A's (before A detects on the interior thread); then refresh_ghosts exchanges and scatters them.
  void gather_halo();
  void refresh_on_device();
  void refresh_on_host();
};

}  // namespace cg
