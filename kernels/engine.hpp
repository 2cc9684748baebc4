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
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/vec3.hpp"
#include "errors.hpp"
#include "host/huge_pages.hpp"

namespace cg {

enum class Backend { cpu, cuda, automatic };
enum class Fields { basic, full };
enum class Precision { fp32, fp64 };

const char* to_string(Backend b);
const char* to_string(Fields f);
const char* to_string(Precision p);

// True when a CUDA device is usable in this process (false in builds without CUDA).
bool cuda_available();
// Number of usable CUDA devices (0 in builds without CUDA or without a GPU).
int cuda_device_count();

struct StageTime {
  std::string name;
  double seconds;
};
using StageTimes = std::vector<StageTime>;

// Contacts as CONTRACT §2: sorted by (id_a, id_b), id_a < id_b, world frame.
template <class Real>
struct Contacts {
  // HostVector: a resize leaves new elements uninitialised (no zero sweep of gigabytes before the
  // engine or a receive overwrites them) and large arrays sit on huge pages.
  HostVector<std::int64_t> id_a, id_b;
  HostVector<Vec3<Real>> position_on_a, position_on_b, normal_on_b;
  HostVector<Real> distance;
  bool full = false;  // the four optional datasets below are filled
  HostVector<Vec3<Real>> local_point_a, local_point_b, lateral_friction_dir1, lateral_friction_dir2;

  std::size_t size() const { return id_a.size(); }
  void reserve(std::size_t k,
               bool with_full);  // room for k rows in every field (the optional ones when with_full)
  void resize(std::size_t k, bool with_full);  // k rows, each field allocated exactly once (reserve first)
};

// The bodies handed to the engine: bounding spheres in the world frame (host memory).
// Invariant: ids strictly ascending (so local index order == id order).
// A report mask byte per body (BodiesView::report, DeviceBodiesView::report): a pair (a < b) is
// reported iff report[a] has kReportedBit (the owner of the smaller id reports) and not both
// report[a] and report[b] have kPairedBit (their pairs were found elsewhere: a rank's boundary bodies
// against its ghosts, after its owned bodies were detected alone).
constexpr std::uint8_t kReportedBit = 1, kPairedBit = 2;

struct BodiesView {
  std::span<const Vec3<double>> position;
  std::span<const double> radius;
  std::span<const std::int64_t> id;      // empty: ids are 0 … n-1
  std::span<const std::uint8_t> report;  // empty: all pairs; else see kReportedBit, kPairedBit
  std::size_t size() const { return radius.size(); }
};

// Axis-aligned bounds of the bounding spheres' boxes, and the largest radius.
struct Bounds {
  Vec3<double> lo{0, 0, 0}, hi{0, 0, 0};
  double r_max = 0;
  std::size_t count = 0;
  double r_sum[3] = {0, 0, 0};  // Σ r, Σ r², Σ r³: the radius moments of the cell-size model
  void merge(const Bounds& o);
};

// Validates every body (finite centre, finite radius > 0) and returns the bounds.
// Throws InputError naming the first bad body by id.
Bounds compute_bounds(const BodiesView& bodies);

// The shared frame of a run: local origin (double) and cell edge. Every rank of an MPI run uses the
// same frame, so every rank computes bit-identical local coordinates and contact data.
struct Frame {
  Vec3<double> origin{0, 0, 0};
  double cell_size = 0;
};

// Smallest valid cell edge for these bounds: 2·r_max plus a margin that covers the rounding of
// c ± r in the local frame, so a body never spans more than two cells per axis.
double min_cell_size(const Bounds& b, Precision p);

// How the cell edge is chosen when none is requested (EngineOptions::cell_size = 0).
enum class CellChoice {
  tuned,     // tuned_cell_size(): the edge that minimises the modelled cost of the sort and pair stages
  smallest,  // min_cell_size(): the largest diameter + rounding margin (Le Grand's choice)
};

// The cell edge in [1, 3] × min_cell_size() that minimises a cost model of the stages that depend on
// it, per body: e + kPairWeight · N · e² / cells, where e = E[(1 + 2r/c)³] is the expected number of
// (cell, body) entries per body (exact for uniformly placed centres, from the radius moments),
// N · e² / cells twice the expected pair-walk steps per body (Poisson occupancy of the cells that
// cover the bounds), and kPairWeight the measured cost of a walk step relative to one entry
// (sort + fill). Larger cells mean fewer entries to sort but more pairs to walk: dilute scenes of
// similar radii gain ~2× larger cells, dense or strongly polydisperse ones keep the smallest. Only
// speed depends on the choice: contacts are the same for every valid cell edge.
double tuned_cell_size(const Bounds& b, Precision p);
inline constexpr double kPairWeight =
    0.03;  // fit: H100, 2^24 uniform spheres, fp32, cells 3–6 (BENCHMARKS §3)

// Frame for the bounds; requested_cell_size 0 picks the cell by `choice`. Throws UsageError if the
// requested size is too small, InputError if the grid cannot be encoded (see GridPlan).
Frame make_frame(const Bounds& b, double requested_cell_size, Precision p,
                 CellChoice choice = CellChoice::tuned);

// The grid of one detect() call: cells covering the bodies' bounds in the shared frame.
// Cell keys use 32 bits when the grid has < 2^32 cells, else 64 bits (< 2^63 cells); beyond that,
// or beyond 2^22 cells per axis in fp32 (2^40 in fp64), plan_grid() throws InputError.
struct GridPlan {
  Frame frame;
  std::uint32_t base[3] = {0, 0, 0};  // cell coordinate (even) of the grid's first cell in the frame
  std::uint32_t dims[3] = {1, 1, 1};
  std::uint32_t half[3] = {1, 1, 1};
  int half_bits = 0;
  int key_bits = 3;
  bool key64 = false;
  std::uint64_t cell_count() const { return std::uint64_t(dims[0]) * dims[1] * dims[2]; }
};
GridPlan plan_grid(const Bounds& local, const Frame& frame, Precision p);

// Bodies already in CUDA DEVICE memory, for simulations that keep their state on the GPU and call
// the engine every step (Engine::detect_device*). Pointers are device pointers on the engine's device
// (EngineOptions::device); the engine only reads them. Body i has id i (local indices).
// Synchronisation: the arrays must be complete when detect_device* is called. Work queued on the
// legacy default stream is ordered before the engine's (blocking) stream; work on a caller's
// non-blocking stream must be synchronised by the caller (cudaStreamSynchronize) first.
struct DeviceBodiesView {
  const double* position = nullptr;      // DEVICE, 3·count doubles: x, y, z of body i at 3i … 3i+2
  const double* radius = nullptr;        // DEVICE, count doubles
  const std::uint8_t* report = nullptr;  // DEVICE, count bytes, or null: all pairs (as BodiesView)
  std::size_t count = 0;
};

// Contacts left in DEVICE memory, owned by the engine: valid until the engine's next detect call or
// its destruction. Same rows and order as Contacts (sorted by (id_a, id_b)); ids are local indices.
// The four `full` arrays are null unless the engine runs with Fields::full.
template <class Real>
struct DeviceContactsView {
  std::size_t count = 0;
  bool full = false;
  const std::int64_t* id_a = nullptr;
  const std::int64_t* id_b = nullptr;
  const Vec3<Real>* position_on_a = nullptr;
  const Vec3<Real>* position_on_b = nullptr;
  const Vec3<Real>* normal_on_b = nullptr;
  const Real* distance = nullptr;
  const Vec3<Real>* local_point_a = nullptr;
  const Vec3<Real>* local_point_b = nullptr;
  const Vec3<Real>* lateral_friction_dir1 = nullptr;
  const Vec3<Real>* lateral_friction_dir2 = nullptr;
};

struct EngineOptions {
  Backend backend = Backend::automatic;
  Fields fields = Fields::basic;
  double cell_size = 0;                        // 0: chosen by cell_choice
  CellChoice cell_choice = CellChoice::tuned;  // how, when cell_size is 0
  int threads = 0;                             // CPU backend threads; 0: all hardware threads
  int device = -1;                             // CUDA device; -1: current
};

// Counters of one run (for tests and the summary).
struct EngineStats {
  std::uint64_t bodies = 0, entries = 0, pair_tests = 0, contacts = 0;
  int key_bits = 0;
  double cell_size = 0;                  // the cell edge used
  std::uint64_t peak_device_bytes = 0;   // CUDA: device workspace held after the call (never shrinks)
  std::uint64_t device_allocations = 0;  // CUDA: cudaMalloc calls made by this call (0 once warm)
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

  // Resident bodies: a simulation's state kept where the backend computes (host memory for the CPU
  // backend, DEVICE memory for CUDA) between detect calls, refreshed in row ranges (a halo exchange)
  // without moving the rest. set_resident copies `bodies` (ids implied: row i is body i; report as in
  // BodiesView); read_resident / write_resident copy the positions and radii of rows
  // [first, first + count) out and in (UsageError outside the rows); detect_resident detects among the
  // resident rows and keeps the contacts where they were computed (CUDA: as detect_device_resident),
  // returning their number; resident_contacts() gives them in host memory (ids are row indices;
  // CUDA: downloaded on the first request, which must come before the engine's next detection,
  // else UsageError).
  void set_resident(const BodiesView& bodies);
  std::size_t resident_size() const;
  void read_resident(std::size_t first, std::size_t count, Vec3<double>* position, double* radius);
  void write_resident(std::size_t first, std::size_t count, const Vec3<double>* position,
                      const double* radius);
  std::size_t detect_resident(std::optional<Frame> frame = std::nullopt);
  const Contacts<Real>& resident_contacts();
  // Page-locks host memory that read_resident / write_resident use again and again (CUDA:
  // cudaHostRegister, so the copies run at the link's speed; CPU: nothing to do). false when the
  // driver refuses (the copies stay pageable). unpin_host before that memory is freed.
  bool pin_host(void* p, std::size_t bytes);
  void unpin_host(void* p);

  Backend backend() const;  // the resolved backend (never automatic)
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
