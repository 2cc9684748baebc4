#pragma once
// The contactgrid engine: Le Grand's uniform-grid broad phase + exact narrow phase on one rank.
// g++-safe public header: no CUDA types. Backends (CPU, CUDA) are selected at run time; both run the
// same stages over the same host/device math in kernels/core/.
//
// Data flow of one detect() call:
//   bounds (double) → frame (origin, cell size) → grid plan (dims, key width)
//   → pack (world double → local Real) → cell entries (home + phantom, control bits)
//   → radix sort by cell key → pair count → scan → pair fill → sort pairs by (a, b)
//   → narrow phase (requested fields) → contacts in world frame, sorted by (id_a, id_b)
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "bodies.hpp"
#include "broad_phase.hpp"
#include "contacts.hpp"
#include "core/vec3.hpp"
#include "errors.hpp"
#include "grid_plan.hpp"
#include "history.hpp"
#include "pair_estimate.hpp"

namespace cg {

enum class Backend { cpu, cuda, automatic };
enum class Fields { basic, full };

const char* to_string(Backend b);
const char* to_string(Fields f);

// True when a CUDA device is usable in this process (false in builds without CUDA).
bool cuda_available();

// The broad phase a call runs: `requested`, or for automatic choose_broad_phase's pick for `backend`
// (automatic: CUDA where a device is usable), whose grid pays more for crowded cells on a GPU, and for
// `skin` (the call keeps its candidates). Every pick gives the same contacts, bit for bit.
BroadPhase resolved_broad_phase(BroadPhase requested, const Bounds& b, Precision p, Backend backend,
                                bool skin = false);
// Number of usable CUDA devices (0 in builds without CUDA or without a GPU).
int cuda_device_count();

struct StageTime {
  std::string name;
  double seconds;
};
using StageTimes = std::vector<StageTime>;

struct EngineOptions {
  Backend backend = Backend::automatic;
  Fields fields = Fields::basic;
  double cell_size = 0;                        // 0: chosen by cell_choice
  CellChoice cell_choice = CellChoice::tuned;  // how, when cell_size is 0
  // The broad phase (broad_phase.hpp): automatic picks one per call from the bodies' radii
  // (choose_broad_phase); every one gives the same contacts, bit for bit.
  BroadPhase broad_phase = BroadPhase::automatic;
  int threads = 0;  // CPU backend threads; 0: all hardware threads
  int device = -1;  // CUDA device; -1: current
  // CUDA: the most device memory the engine's workspace may hold, in bytes (0: what the device has
  // free); a call that needs more throws ResourceError. CONTACTGRID_DEVICE_MEMORY_LIMIT (docs/GPU.md)
  // caps it too: the smaller of the two holds.
  std::uint64_t device_memory_limit = 0;
  // CUDA: the engine's stream at the device's highest priority, so that its kernels' blocks are
  // scheduled before the pending blocks of engines at the default priority on the same device (the
  // step loop's boundary engine, whose few blocks would otherwise wait for the interior's large grids).
  // The same results either way.
  bool high_priority = false;
  // Ellipsoid narrow phase (scenes with ellipsoids only; core/ellipsoid_contact.hpp SolverSettings):
  // Newton stops when the tangential gradient is <= tolerance × (largest semi-axis of A + of B);
  // iteration cap per start. 0: the precision's default (fp32 2e-5, fp64 1e-11; 40 iterations).
  double ellipsoid_tolerance = 0;
  int ellipsoid_max_iterations = 0;
  // Precision::mixed (Engine<double> only; UsageError for Engine<float>): the broad phase (pack …
  // order) in float with enlarged spheres (broad_margin), the narrow phase in double from the world
  // coordinates. Contacts bit-identical to Engine<double> without it (same frame).
  bool fp32_broad_phase = false;
  // Verlet skin (world length, >= 0): 0 detects from scratch every call (the default). > 0 keeps the
  // candidate pairs across calls: a call builds them from bounding spheres inflated by skin/2 (the
  // cell edge grows to cover the inflated radii), and a later call on the same bodies (same count,
  // ids, report mask and shape presence) whose centres moved by at most d and radii grew by at most g
  // since that build, 2·(d + g) <= skin, skips entries/sort/pairs/order and runs pack + narrow over
  // the kept list (in scenes of the centre cut the list is also cut by the centre line with the skin
  // as its margin, and d counts turns: core/centre_cut.hpp). Either way the contacts are those of a
  // skin-0 detection, bit for bit.
  double skin = 0;
  // Contact identity across calls (docs/FORMAT.md §2's history fields; core/history.hpp): every call's
  // contacts carry age and previous_row against this engine's previous call (the first call, and the
  // first after reset_history(): every pair new). Pairs are keyed by global ids: the contacts' ids
  // (BodiesView::id), or for device and resident bodies their `id` rows where given (row indices
  // otherwise). Computed where the contacts are delivered: the host for host bodies, the device for
  // device bodies (detect_device*, CUDA resident bodies).
  bool history = false;
  // Runaway work (pair_estimate.hpp): before its pair stage the broad phase estimates the pair tests
  // from the cells' occupancy; on_pair_estimate (when set) sees the estimate, and one above
  // max_pair_tests (0: no limit) throws LimitError (exit code 9) before the pair stage runs.
  std::uint64_t max_pair_tests = 0;
  std::function<void(const PairEstimate&)> on_pair_estimate{};
  // The pair stage's progress (PairLimits::on_progress): tests done so far, then finished — the host
  // backend's always, the CUDA backend's when the estimate is far above the usual (follows_progress).
  std::function<void(std::uint64_t done, bool finished)> on_pair_progress{};
  // The skin chosen by the engine (skin is then ignored): from the largest displacement per call it
  // observes and the measured cost of its builds and reuses, the skin whose mean cost per call is
  // lowest (kernels/skin_tuner.hpp). For an engine called once per step of a simulation.
  bool skin_auto = false;
};

// True when the engine keeps candidate lists across calls (a skin, given or automatic): `auto` then
// keeps the grid broad phase (resolved_broad_phase's `skin`), whose builds the kept lists feed.
inline bool keeps_candidates(const EngineOptions& o) { return o.skin != 0 || o.skin_auto; }

// Counters of one run (for tests and the summary).
struct EngineStats {
  std::uint64_t bodies = 0, entries = 0, pair_tests = 0, contacts = 0;
  std::uint64_t candidates =
      0;  // candidate pairs the narrow phase decided (>= contacts; = with the default filter)
  int key_bits = 0;
  double cell_size = 0;                       // the cell edge used (levels: of the top level)
  BroadPhase broad_phase = BroadPhase::grid;  // the broad phase that ran (never automatic)
  int levels = 0;                             // BroadPhase::levels: the levels of the hierarchy
  std::uint64_t peak_device_bytes = 0;        // CUDA: device workspace held after the call (never shrinks)
  std::uint64_t device_allocations = 0;       // CUDA: cudaMalloc calls made by this call (0 once warm)
  // Scenes with ellipsoids: how many bodies are ellipsoids; candidates whose solve needed the
  // ellipsoid core's safety net (extra starts, `fallback`) and those whose winning minimiser still
  // missed the tolerance (`converged` false: the row is the best minimum found, flagged here).
  std::uint64_t ellipsoids = 0, narrow_fallbacks = 0, narrow_unconverged = 0;
  // Candidates whose first start the cheap certificates did not settle, so the settle pass ran them
  // (`narrow_unsettled`), and those no certificate settled, so the whole start set ran (`narrow_hard`;
  // the device's second and third narrow passes; the same counts on both backends).
  std::uint64_t narrow_unsettled = 0, narrow_hard = 0;
  // CUDA, scenes with ellipsoids: seconds of the narrow stage's triage pass (every candidate), settle
  // pass and hard pass (each with its selection); the rest of the stage is the scan and the rows. The
  // host runs all three in one loop per candidate and leaves them 0.
  double narrow_triage_s = 0, narrow_settle_s = 0, narrow_hard_s = 0;
  // Scenes with ellipsoids: runs of the general ellipsoid solve (each triage's first start, each hard
  // pair's whole set), the evaluations of f (value, gradient, Hessian at one normal) they made, and the
  // most one run made: mean = narrow_evaluations / narrow_solver_runs. The same on both backends.
  std::uint64_t narrow_solver_runs = 0, narrow_evaluations = 0, narrow_max_evaluations = 0;
  // fp32: contact rows whose local centres were closer than fp32 resolves a normal (fp32_resolves,
  // core/narrow.hpp), recomputed in fp64 from the world coordinates and rounded to float.
  std::uint64_t fp64_rows = 0;
  // EngineOptions::skin > 0: candidate lists built and reused since the engine was made (the only
  // counters kept across calls), and the largest displacement and radius growth the last skin check
  // measured (0 when the call rebuilt without a check: first call, other bodies).
  std::uint64_t candidate_builds = 0, candidate_reuses = 0;
  double skin_displacement = 0, skin_growth = 0;
  double skin = 0;  // the skin of the kept list (its build's; 0: none kept)
  // CUDA, the grid's pair stage: the walks of the cells it made (1; 2 where its candidates outgrew the
  // room of their direct write: the fill walk, or a cell-order build's second count); 0 elsewhere.
  int pair_walks = 0;
};

// Engine::resident_extent: where the resident rows are and how far they moved.
struct ResidentExtent {
  Bounds bounds;            // of the resident rows, as compute_bounds
  double displacement = 0;  // the largest distance of a resident centre from its place at the last
                            // mark_resident() (0 without a mark since the rows were set)
};

template <class Real>
class Engine {
 public:
  explicit Engine(EngineOptions options);
  ~Engine();
  Engine(Engine&&) noexcept;
  Engine& operator=(Engine&&) noexcept;

  // All contacts among `bodies`. `frame`: the shared frame of a multi-rank run; absent, the engine
  // builds one from the bodies' bounds and options.cell_size.
  Contacts<Real> detect(const BodiesView& bodies, std::optional<Frame> frame = std::nullopt);
  // The same detection from bounds the caller already has: `bounds` must be compute_bounds(bodies)
  // (which validated the bodies), as a caller that chose the precision mode from them holds
  // (precision_choice.hpp; the Python module's precision "auto"); the engine skips its own pass over
  // the bodies. The same contacts as detect(bodies, frame).
  Contacts<Real> detect(const BodiesView& bodies, const Bounds& bounds,
                        std::optional<Frame> frame = std::nullopt);

  // The same detection for bodies already on the GPU (CUDA backend only, else UsageError). Bounds and
  // validation run on the device (same InputError texts as compute_bounds); results are bit-identical
  // to detect() on the same values. Returns when the results are complete. Example, once per step:
  //
  //   cg::Engine<double> engine({.backend = cg::Backend::cuda});   // persistent device workspace
  //   double *d_pos, *d_rad;                                        // 3n and n doubles, cudaMalloc'd
  //   ...                                                           // the simulation updates them
  //   cg::DeviceBodiesView bodies{.position = d_pos, .radius = d_rad, .count = n};
  //   cg::Contacts<double> c = engine.detect_device(bodies);        // host contacts, ids 0 … n-1
  //   cg::DeviceContactsView<double> dc = engine.detect_device_resident(bodies);  // stays on GPU
  //   my_solver_kernel<<<...>>>(dc.count, dc.id_a, dc.id_b, dc.normal_on_b, dc.distance);
  //
  // detect_device() = detect_device_resident() + one download (stage "download").
  Contacts<Real> detect_device(const DeviceBodiesView& bodies, std::optional<Frame> frame = std::nullopt);
  DeviceContactsView<Real> detect_device_resident(const DeviceBodiesView& bodies,
                                                  std::optional<Frame> frame = std::nullopt);
  // The rows of a view of this engine's last detection copied to host memory (CUDA backend).
  Contacts<Real> download(const DeviceContactsView<Real>& view);
  // The bounds of bodies on the GPU (CUDA backend only, else UsageError), validated as detect_device
  // validates them (same InputError texts): what a caller chooses a precision mode from
  // (precision_choice.hpp) before it makes the engine of that mode. `ellipsoids`: their number.
  Bounds device_bounds(const DeviceBodiesView& bodies, std::size_t* ellipsoids = nullptr);

  // Resident bodies: a simulation's state kept where the backend computes (host memory for the CPU
  // backend, DEVICE memory for CUDA) between detect calls, refreshed in row ranges (a halo exchange)
  // without moving the rest. set_resident copies `bodies` (ids implied: row i is body i; report as in
  // BodiesView; shape rows as in BodiesView, all three or none); read_resident / write_resident copy
  // the positions and radii of rows [first, first + count) out and in (UsageError outside the rows);
  // BodiesView::id, when given to set_resident, is the rows' global ids (strictly ascending): the keys
  // of the contact history (EngineOptions::history) only; the contacts' ids stay row indices;
  // read_resident_shapes / write_resident_shapes the semi-axes and orientations of rows (a null
  // pointer: that field is left alone; UsageError when the rows were set without shape rows; a body's
  // kind stays the one set, and an ellipsoid whose semi-axes change needs its bounding radius, the
  // largest semi-axis, written with write_resident); detect_resident detects among the
  // resident rows and keeps the contacts where they were computed (CUDA: as detect_device_resident),
  // returning their number; resident_contacts() gives them in host memory (ids are row indices;
  // CUDA: downloaded on the first request, which must come before the engine's next detection,
  // else UsageError).
  //
  // A granular simulation's loop with a skin (EngineOptions::skin): every call returns the contacts of
  // the current bodies; most calls reuse the candidate list of an earlier one (EngineStats says which):
  //
  //   cg::Engine<double> engine({.skin = 0.1 * r_min});  // candidates kept while motion < skin/2
  //   engine.set_resident(cg::BodiesView{centre, radius, {}, {}});
  //   for (int step = 0; step < steps; ++step) {
  //     engine.write_resident(0, n, new_centre, radius);   // the integrator's positions
  //     std::size_t k = engine.detect_resident();           // reuse or rebuild, same contacts
  //   }
  //   // engine.stats().candidate_reuses / candidate_builds: how often the list was kept
  //
  // Ellipsoids rotate in place: set_resident with shape rows, then per step
  //   engine.write_resident_shapes(0, n, nullptr, new_orientation);  // semi-axes kept
  void set_resident(const BodiesView& bodies);
  // The resident rows changed where they are, as a migration changes a rank's bodies: rows `leaving`
  // (strictly ascending) removed, and arrival j (row j of `arrivals`) inserted before old row at[j]
  // (non-decreasing, at most resident_size(); arrivals at one place in their order). The same rows
  // as set_resident of the spliced arrays, without moving the rows that stay through the host (CUDA:
  // the arrivals, the leaving rows and the places uploaded, the rows rewritten on the device). The
  // arrivals carry every field the rows were set with (ids, report, shape rows), and no other;
  // UsageError otherwise (without rows: set_resident of the arrivals). As after set_resident, the next
  // detection builds and there is no mark.
  void splice_resident(std::span<const std::size_t> leaving, std::span<const std::size_t> at,
                       const BodiesView& arrivals);
  std::size_t resident_size() const;
  void read_resident(std::size_t first, std::size_t count, Vec3<double>* position, double* radius);
  void write_resident(std::size_t first, std::size_t count, const Vec3<double>* position,
                      const double* radius);
  void read_resident_shapes(std::size_t first, std::size_t count, Vec3<double>* semi_axes,
                            Quat<double>* orientation);
  void write_resident_shapes(std::size_t first, std::size_t count, const Vec3<double>* semi_axes,
                             const Quat<double>* orientation);
  std::size_t detect_resident(std::optional<Frame> frame = std::nullopt);
  const Contacts<Real>& resident_contacts();
  // A step loop's frame and rebuild check where the rows are (CUDA: on the device, one read back of a
  // few values; no centre crosses to the host): mark_resident remembers the resident centres;
  // resident_extent validates the rows and returns their bounds (as compute_bounds: the same
  // InputError texts, a bad row named by ids[row] when `ids` is given, else by its row index) and the
  // largest displacement since the mark. Bit-identical on both backends (min / max are exact; the
  // radius moments of Bounds::r_sum are summed in each backend's order, as compute_bounds' threads
  // and device_bounds do).
  void mark_resident();
  ResidentExtent resident_extent(std::span<const std::int64_t> ids = {});
  // Page-locks host memory that read_resident / write_resident, or detect's host arrays, use again
  // and again (CUDA: cudaHostRegister, so the copies run at the link's speed: detect's arrays then go
  // up straight instead of through the pinned ring's host copy; CPU: nothing to do). false when the
  // driver refuses (the copies stay pageable). unpin_host before that memory is freed.
  bool pin_host(void* p, std::size_t bytes);
  void unpin_host(void* p);

  // A halo's rows, moved where the rows are (the step loop's ghosts between two layouts): lists of
  // resident rows kept by the engine (CUDA: on the device) and their positions and radii (and
  // orientations) packed into, or unpacked from, buffers the engine owns and reuses (CUDA: page-locked
  // host memory, allocated once and grown only), so that a step moves only those rows' bytes. A packed
  // row is its position (3 doubles) and radius, then with `orientations` its orientation (w, x, y, z):
  // packed_row_bytes. Lists 0 … kRowLists - 1; a list holds until set again or the rows change
  // (set_resident, splice_resident: UsageError when used after).
  static constexpr int kRowLists = 4;
  static constexpr std::size_t packed_row_bytes(bool orientations) { return orientations ? 64 : 32; }
  // List `list` := `rows` (each < resident_size(); UsageError otherwise).
  void set_row_list(int list, std::span<const std::size_t> rows);
  // The rows of list `list`, packed in the list's order, in the engine's gather buffer (valid until
  // the next gather_rows).
  std::span<const std::byte> gather_rows(int list, bool orientations);
  // The engine's scatter buffer, sized for `count` packed rows, for the caller to fill (an MPI receive)
  // before scatter_rows; valid until the next scatter_buffer.
  std::span<std::byte> scatter_buffer(std::size_t count, bool orientations);
  // The scatter buffer's first rows written into the rows of list `list`, in the list's order.
  void scatter_rows(int list, bool orientations);
  // The rows of `from`'s list `from_list` written into this engine's rows of list `to_list` (the same
  // length), where the rows are (CUDA: device to device; both engines on one device, one backend).
  void copy_rows(Engine& from, int from_list, int to_list, bool orientations);
  // The resident rows whose centre coordinate along `axis` (0 x, 1 y, 2 z) is not inside the open
  // interval (lo, hi) — or is not a number — ascending (CUDA: selected on the device, only their
  // indices downloaded): a step loop's candidates for leaving a slab or lying near its cuts, which it
  // then tests exactly on the host.
  std::vector<std::size_t> rows_outside(int axis, double lo, double hi);

  // EngineOptions::history: the next call's pairs are all new (a new simulation on this engine).
  void reset_history();
  // EngineOptions::history: the previous call's pair keys and ages (CUDA: downloaded), and the
  // history the next call's rows are matched against (keys strictly ascending, ages >= 1): a caller
  // that moves bodies between engines carries their pairs' identity with them (src/simulate).
  const ContactHistory& history();
  void set_history(ContactHistory history);

  // The skin of the next build (>= 0, finite; UsageError otherwise); a kept list is checked with the
  // skin it was built with until then. Turns EngineOptions::skin_auto off: the caller chooses.
  void set_skin(double skin);
  // The next detection builds its candidate list instead of checking the kept one (a caller that
  // laid its rows out again: the step loop's rebuild with the same resident rows, written in place).
  void rebuild_candidates();

  Backend backend() const;      // the resolved backend (never automatic)
  Precision precision() const;  // fp32, fp64, or mixed (Engine<double> with fp32_broad_phase)
  const StageTimes& times() const;
  const EngineStats& stats() const;
  const EngineOptions& options() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> m_impl;
};

extern template class Engine<float>;
extern template class Engine<double>;

}  // namespace cg
