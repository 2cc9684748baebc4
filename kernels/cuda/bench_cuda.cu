// contactgrid_cuda_bench: the CUDA engine on uniform random spheres, device-resident input, warm.
// For N = 2^min … 2^max (step 2 by default), the three precision modes (fp32, mixed, fp64): per-stage medians
// (CUDA events), the total wall time of Engine::detect_device_resident (bounds + plan + stages + host syncs;
// L2 flushed before every run), spheres/s, contacts and entries per sphere, device workspace per sphere, and
// the ratio of the sort stage and of the total to the CUB sort floor measured here for the same number of
// (cell, body) entries and key bits (SortPairs u32 key + u32 value, L2 flushed, median). Transfers are
// reported apart: upload = input (positions + radii) H2D from pageable host memory, download = the engine's
// "download" stage (contacts → host vectors).
//
// Scene (6th argument): `spheres` (default): radii U[0.5, 1], centres U[0, L)^3 with L = 2.65·N^(1/3);
// `ellipsoids`: semi-axes each U[0.25, 1] (aspect <= 1:4), orientations uniform on SO(3) (Shoemake),
// bounding radius = largest semi-axis; `mixed`: every other body such an ellipsoid, the rest spheres of
// radius U[0.5, 1]. For the shape scenes L is calibrated at 2^16 on the GPU so that contacts/N = 0.4
// (the issue's scene; two secant steps on L^-3, printed). All from a seeded splitmix64.
// usage: contactgrid_cuda_bench [min_log2=16] [max_log2=26] [step=2] [runs=20] [cell=auto]
//                               [scene=spheres|ellipsoids|mixed] [skin=0]
// skin > 0 adds the steps table (EngineOptions::skin): `runs` steps in which every centre moves by a
// random vector of length <= skin/10 (a device kernel, not timed), detect_device_resident per step
// with the skin (reuse or rebuild) and without (every step from scratch, skin 0), L2 not flushed
// (a simulation's step follows its integrator).
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <cub/device/device_radix_sort.cuh>
#include <functional>
#include <iomanip>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "cuda/device_buffer.cuh"
#include "engine.hpp"
#include "timing.hpp"

namespace {

// Cell edge of every run (--cell-size of the CLI): 0 and g_cell_choice (auto: tuned, min: smallest).
double g_cell_size = 0.0;
cg::CellChoice g_cell_choice = cg::CellChoice::tuned;

using cg::median;
using cg::cuda::DeviceBuffer;

constexpr std::size_t kFlushBytes = std::size_t(256) << 20;

std::uint64_t splitmix64(std::uint64_t& s) {
  std::uint64_t x = (s += 0x9E3779B97F4A7C15ull);
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}
double unit(std::uint64_t& s) { return double(splitmix64(s) >> 11) * 0x1.0p-53; }

struct Flusher {
  DeviceBuffer<std::byte> buf;
  int tick = 0;
  Flusher() { buf.reserve(kFlushBytes, false); }
  void operator()() {  // evicts L2 (50 MiB) before a timed run; not timed
    CG_CUDA_CHECK(cudaMemsetAsync(buf.data(), ++tick & 0xFF, kFlushBytes));
    CG_CUDA_CHECK(cudaDeviceSynchronize());
  }
};

__global__ void random_keys(std::uint32_t* k, std::uint32_t* v, std::uint32_t n, std::uint32_t mask,
                            std::uint64_t seed) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  std::uint64_t x = seed ^ (std::uint64_t(i) * 0xD1B54A32D192ED03ull);
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  k[i] = std::uint32_t(x ^ (x >> 31)) & mask;
  v[i] = i;
}

// Median time (ms) of cub::DeviceRadixSort::SortPairs (DoubleBuffer, u32 + u32) over `bits` bits of
// `n` random keys; L2 flushed before each run.
double sort_floor_ms(std::uint32_t n, int bits, int runs, Flusher& flush) {
  DeviceBuffer<std::uint32_t> k[2], v[2];
  for (int j = 0; j < 2; ++j) {
    k[j].reserve(n, false);
    v[j].reserve(n, false);
  }
  const std::uint32_t mask = bits >= 32 ? 0xFFFFFFFFu : ((1u << bits) - 1);
  cub::DoubleBuffer<std::uint32_t> dk(k[0].data(), k[1].data()), dv(v[0].data(), v[1].data());
  std::size_t temp_bytes = 0;
  CG_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, dk, dv, int(n), 0, bits));
  DeviceBuffer<std::byte> temp;
  temp.reserve(temp_bytes, false);
  cudaEvent_t e0, e1;
  CG_CUDA_CHECK(cudaEventCreate(&e0));
  CG_CUDA_CHECK(cudaEventCreate(&e1));
  std::vector<double> t;
  for (int r = 0; r < runs + 3; ++r) {
    random_keys<<<(n + 255) / 256, 256>>>(dk.Current(), dv.Current(), n, mask, 77 + r);
    CG_CUDA_CHECK(cudaGetLastError());
    flush();
    CG_CUDA_CHECK(cudaEventRecord(e0));
    CG_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp.data(), temp_bytes, dk, dv, int(n), 0, bits));
    CG_CUDA_CHECK(cudaEventRecord(e1));
    CG_CUDA_CHECK(cudaEventSynchronize(e1));
    float ms = 0;
    CG_CUDA_CHECK(cudaEventElapsedTime(&ms, e0, e1));
    if (r >= 3) t.push_back(ms);
  }
  cudaEventDestroy(e0);
  cudaEventDestroy(e1);
  return median(t);
}

// A bench scene in host memory, uploaded once per N (input arrays as DeviceBodiesView wants them).
struct HostScene {
  std::vector<double> pos, rad, semi, quat;
  std::vector<cg::Shape> shape;  // empty: spheres only
};

enum class SceneKind { spheres, ellipsoids, mixed };

HostScene make_scene(SceneKind kind, std::uint64_t n, double density_scale, std::uint64_t seed) {
  HostScene h;
  h.pos.resize(3 * n);
  h.rad.resize(n);
  if (kind != SceneKind::spheres) {
    h.shape.assign(n, cg::Shape::sphere);
    h.semi.assign(3 * n, 1.0);
    h.quat.assign(4 * n, 0.0);
  }
  const double L = 2.65 * density_scale * std::cbrt(double(n));
  for (std::uint64_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) h.pos[3 * i + k] = unit(seed) * L;
    const bool ellipsoid = kind == SceneKind::ellipsoids || (kind == SceneKind::mixed && i % 2 == 1);
    if (!ellipsoid) {
      h.rad[i] = 0.5 + 0.5 * unit(seed);
      if (!h.quat.empty()) h.quat[4 * i] = 1.0;
      continue;
    }
    double r = 0;
    for (int k = 0; k < 3; ++k) r = std::max(r, h.semi[3 * i + k] = 0.25 + 0.75 * unit(seed));
    const double u1 = unit(seed), u2 = 2 * M_PI * unit(seed), u3 = 2 * M_PI * unit(seed);
    const double s1 = std::sqrt(1 - u1), s2 = std::sqrt(u1);
    const double q[4] = {s2 * std::cos(u3), s1 * std::sin(u2), s1 * std::cos(u2), s2 * std::sin(u3)};
    const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int k = 0; k < 4; ++k) h.quat[4 * i + k] = q[k] / norm;
    h.rad[i] = r;
    h.shape[i] = cg::Shape::ellipsoid;
  }
  return h;
}

// The scene on the device (the caller's arrays of a simulation).
struct DeviceScene {
  DeviceBuffer<double> pos, rad, semi, quat;
  DeviceBuffer<cg::Shape> shape;
  double upload_ms = 0;
  cg::DeviceBodiesView view(std::uint64_t n) const {
    cg::DeviceBodiesView v{pos.data(), rad.data(), nullptr, n};
    if (shape.capacity()) {
      v.shape = shape.data();
      v.semi_axes = semi.data();
      v.orientation = quat.data();
    }
    return v;
  }
};

template <class T>
void upload(DeviceBuffer<T>& d, const std::vector<T>& h) {
  if (h.empty()) return;
  d.reserve(h.size(), false);
  CG_CUDA_CHECK(cudaMemcpy(d.data(), h.data(), h.size() * sizeof(T), cudaMemcpyHostToDevice));
}

struct Row {
  int log2n;
  const char* prec;
  std::uint64_t n, entries, contacts;
  int key_bits;
  double cell;
  std::map<std::string, double> stage_ms;
  double gpu_sum_ms, total_ms, floor_ms, upload_ms, download_ms, bytes_per_sphere, bytes_no_contacts;
  std::uint64_t candidates, fallbacks, unconverged, unsettled, hard, solver_runs, evaluations,
      max_evaluations;  // narrow stage (shape scenes); over all runs
};

// Contacts per body of the scene at 2^16 with the given density scale (fp32 engine, one run).
double contacts_per_body(SceneKind kind, double scale) {
  const std::uint64_t n = 1u << 16;
  const HostScene h = make_scene(kind, n, scale, 0x5EED0000ull);
  DeviceScene d;
  upload(d.pos, h.pos), upload(d.rad, h.rad), upload(d.semi, h.semi), upload(d.quat, h.quat);
  upload(d.shape, h.shape);
  cg::Engine<float> engine({.backend = cg::Backend::cuda});
  return double(engine.detect_device_resident(d.view(n)).count) / double(n);
}

// One precision mode: Engine<Real>, mixed = Engine<double> with the fp32 broad phase.
template <class Real>
Row bench(int log2n, std::uint64_t n, const DeviceScene& scene, int runs, Flusher& flush,
          bool mixed = false) {
  Row row{};
  row.log2n = log2n;
  row.prec = mixed ? "mixed" : cg::to_string(cg::precision_of<Real>());
  row.n = n;
  row.upload_ms = scene.upload_ms;
  const cg::DeviceBodiesView bodies = scene.view(n);
  {
    cg::Engine<Real> engine({.backend = cg::Backend::cuda,
                             .cell_size = g_cell_size,
                             .cell_choice = g_cell_choice,
                             .fp32_broad_phase = mixed});
    for (int w = 0; w < 3; ++w) engine.detect_device_resident(bodies);
    std::map<std::string, std::vector<double>> stages;
    std::vector<double> total, gpu_sum;
    for (int r = 0; r < runs; ++r) {
      flush();
      const auto t0 = std::chrono::steady_clock::now();
      const cg::DeviceContactsView<Real> c = engine.detect_device_resident(bodies);
      const auto t1 = std::chrono::steady_clock::now();
      total.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      double sum = 0;
      for (const auto& s : engine.times()) {
        stages[s.name].push_back(s.seconds * 1e3);
        if (s.name != "plan") sum += s.seconds * 1e3;
      }
      gpu_sum.push_back(sum);
      row.contacts = c.count;
      if (engine.stats().device_allocations != 0) std::fprintf(stderr, "warning: a warm run allocated\n");
      stages["triage"].push_back(engine.stats().narrow_triage_s * 1e3);
      stages["settle"].push_back(engine.stats().narrow_settle_s * 1e3);
      stages["hard"].push_back(engine.stats().narrow_hard_s * 1e3);
      row.fallbacks += engine.stats().narrow_fallbacks;
      row.unconverged += engine.stats().narrow_unconverged;
    }
    row.candidates = engine.stats().candidates;
    row.unsettled = engine.stats().narrow_unsettled;
    row.hard = engine.stats().narrow_hard;
    row.solver_runs = engine.stats().narrow_solver_runs;
    row.evaluations = engine.stats().narrow_evaluations;
    row.max_evaluations = engine.stats().narrow_max_evaluations;
    for (auto& [name, v] : stages) row.stage_ms[name] = median(v);
    row.total_ms = median(total);
    row.gpu_sum_ms = median(gpu_sum);
    row.entries = engine.stats().entries;
    row.key_bits = engine.stats().key_bits;
    row.cell = engine.stats().cell_size;
    row.bytes_per_sphere = double(engine.stats().peak_device_bytes) / double(n);
    // download: contacts to host vectors (stage "download" of detect_device), median of 3
    std::vector<double> dl;
    for (int r = 0; r < 3; ++r) {
      const cg::Contacts<Real> h = engine.detect_device(bodies);
      for (const auto& s : engine.times())
        if (s.name == "download") dl.push_back(s.seconds * 1e3);
      if (h.size() != row.contacts) std::fprintf(stderr, "error: detect_device and resident disagree\n");
    }
    row.download_ms = median(dl);
    // without the contact output buffer (basic fields: 2 ids + 3 Vec3 + distance per contact)
    row.bytes_no_contacts =
        (double(engine.stats().peak_device_bytes) - double(row.contacts) * (16.0 + 10.0 * sizeof(Real))) /
        double(n);
  }
  row.floor_ms = row.key_bits <= 32
                     ? sort_floor_ms(static_cast<std::uint32_t>(row.entries), row.key_bits, runs, flush)
                     : 0.0;
  return row;
}

// Every centre moved by a random vector of length <= step (per body and step from a hash).
__global__ void random_move(double* pos, std::uint32_t n, double step, std::uint64_t seed) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  std::uint64_t s = seed ^ (std::uint64_t(i) * 0xD1B54A32D192ED03ull);
  for (int k = 0; k < 3; ++k) {
    std::uint64_t x = (s += 0x9E3779B97F4A7C15ull);
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    const double u = double((x ^ (x >> 31)) >> 11) * 0x1.0p-53 - 0.5;  // [-1/2, 1/2): |move| <= step
    pos[3 * std::uint64_t(i) + k] += u * (2 * step / 1.7320508075688772);
  }
}

struct SkinRow {
  int log2n;
  const char* prec;
  std::uint64_t builds, reuses;
  double scratch_ms, reuse_ms, build_ms, mean_ms;
  bool same;
};

// `runs` steps of moves <= skin/10: median wall time of detect_device_resident per step without a
// skin (every step from scratch), and with it: of the reused steps, of the rebuilt ones; the mean.
template <class Real>
SkinRow bench_skin(int log2n, std::uint64_t n, const DeviceScene& d, double skin, int runs) {
  SkinRow row{log2n, cg::to_string(cg::precision_of<Real>()), 0, 0, 0, 0, 0, 0, true};
  DeviceBuffer<double> pos;  // the scene's centres, moved step by step
  pos.reserve(3 * n, false);
  CG_CUDA_CHECK(cudaMemcpy(pos.data(), d.pos.data(), 3 * n * sizeof(double), cudaMemcpyDeviceToDevice));
  cg::DeviceBodiesView bodies = d.view(n);
  bodies.position = pos.data();
  cg::Engine<Real> kept(
      {.backend = cg::Backend::cuda, .cell_size = g_cell_size, .cell_choice = g_cell_choice, .skin = skin});
  cg::Engine<Real> scratch(
      {.backend = cg::Backend::cuda, .cell_size = g_cell_size, .cell_choice = g_cell_choice});
  for (int w = 0; w < 3; ++w) scratch.detect_device_resident(bodies), kept.detect_device_resident(bodies);
  std::vector<double> t_scratch, t_reuse, t_build;
  double sum = 0;
  auto wall = [](auto&& f) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  };
  for (int r = 0; r < runs; ++r) {
    random_move<<<unsigned((n + 255) / 256), 256>>>(pos.data(), std::uint32_t(n), skin / 10, 991 + r);
    CG_CUDA_CHECK(cudaDeviceSynchronize());
    std::size_t k_scratch = 0, k_kept = 0;
    t_scratch.push_back(wall([&] { k_scratch = scratch.detect_device_resident(bodies).count; }));
    const std::uint64_t reuses = kept.stats().candidate_reuses;
    const double t = wall([&] { k_kept = kept.detect_device_resident(bodies).count; });
    (kept.stats().candidate_reuses > reuses ? t_reuse : t_build).push_back(t);
    sum += t;
    row.same = row.same && k_scratch == k_kept;
  }
  row.builds = t_build.size();
  row.reuses = t_reuse.size();
  row.scratch_ms = median(t_scratch);
  row.reuse_ms = median(t_reuse);
  row.build_ms = median(t_build);
  row.mean_ms = sum / double(runs);
  return row;
}

// The pinned bandwidth of this host, each way (GB/s): 256 MiB between cudaMallocHost memory and the
// device, median of 5. The floor of a host path is its bytes over these.
struct PinnedBandwidth {
  double h2d = 0, d2h = 0;
};
PinnedBandwidth pinned_bandwidth() {
  const std::size_t bytes = std::size_t(256) << 20;
  void* h = nullptr;
  CG_CUDA_CHECK(cudaMallocHost(&h, bytes));
  std::memset(h, 1, bytes);
  DeviceBuffer<std::byte> d;
  d.reserve(bytes, false);
  auto time = [&](cudaMemcpyKind kind) {
    std::vector<double> t;
    for (int r = 0; r < 5; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      if (kind == cudaMemcpyHostToDevice)
        CG_CUDA_CHECK(cudaMemcpy(d.data(), h, bytes, kind));
      else
        CG_CUDA_CHECK(cudaMemcpy(h, d.data(), bytes, kind));
      t.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    return double(bytes) / median(t) / 1e9;
  };
  PinnedBandwidth bw{time(cudaMemcpyHostToDevice), time(cudaMemcpyDeviceToHost)};
  CG_CUDA_CHECK(cudaFreeHost(h));
  return bw;
}

struct HostPathRow {
  int log2n;
  const char* transfer;
  std::uint64_t contacts;
  double up_bytes, down_bytes, upload_ms, download_ms, total_ms, floor_ms, bytes_floor_ms;
  std::string stages;  // "name ms" of every stage of Engine::times(), medians, in stage order
};

// Host arrays → host contacts (basic fields, fp32, one engine reused: Engine::detect on the scene's
// host arrays) by each CONTACTGRID_CUDA_HOST_PATH (cuda/tuning.hpp: device, the default: the doubles
// up first and the device's bounds; packed: the host's bounds and the 16-byte spheres up; old: the
// host's bounds and the doubles up by each transfer path of tuning.hpp forced through its knobs); the
// first two take the rows straight into the result vectors' locked pool blocks; median wall time of
// `runs` calls and of the upload and download stages. bytes floor = the bytes the row's path moves
// over the pinned bandwidth each way, one way after the other; floor = that plus the device-resident
// total of the same scene (`resident_ms`).
std::vector<HostPathRow> bench_host_path(int log2n, const HostScene& h, int runs, const PinnedBandwidth& bw,
                                         double resident_ms) {
  const std::uint64_t n = h.rad.size();
  cg::BodiesView v{{reinterpret_cast<const cg::Vec3<double>*>(h.pos.data()), n}, {h.rad.data(), n}, {}, {}};
  if (!h.shape.empty()) {
    v.shape = h.shape;
    v.semi_axes = {reinterpret_cast<const cg::Vec3<double>*>(h.semi.data()), n};
    v.orientation = {reinterpret_cast<const cg::Quat<double>*>(h.quat.data()), n};
  }
  std::vector<HostPathRow> rows;
  struct Path {
    const char *name, *up, *down;
    const char* host_path;  // CONTACTGRID_CUDA_HOST_PATH (null: the default, device)
    bool pinned = false;    // the scene's arrays page-locked by Engine::pin_host first
  };
  const Path paths[] = {{"device (default)", nullptr, nullptr, nullptr},
                        {"device, input pinned", nullptr, nullptr, nullptr, true},
                        {"packed", nullptr, nullptr, "packed"},
                        {"old streamed", "streamed", "streamed", "old"},
                        {"old registered", "registered", "registered", "old"},
                        {"old pageable", "pageable", "staged", "old"}};
  const char* knobs[] = {"CONTACTGRID_CUDA_UPLOAD", "CONTACTGRID_CUDA_DOWNLOAD",
                         "CONTACTGRID_CUDA_HOST_PATH"};
  for (const Path& path : paths) {
    const char* values[] = {path.up, path.down, path.host_path};
    for (int k = 0; k < 3; ++k) values[k] ? ::setenv(knobs[k], values[k], 1) : ::unsetenv(knobs[k]);
    cg::Engine<float> engine(
        {.backend = cg::Backend::cuda, .cell_size = g_cell_size, .cell_choice = g_cell_choice});
    std::vector<double> total;
    std::vector<std::string> stage_names;
    std::map<std::string, std::vector<double>> stage_ms;
    HostPathRow row{log2n, path.name, 0, 0, 0, 0, 0, 0, 0, 0, {}};
    // (page-locking reads nothing and writes nothing: the scene stays const)
    void* pos = const_cast<double*>(h.pos.data());
    void* rad = const_cast<double*>(h.rad.data());
    const bool pinned = path.pinned && engine.pin_host(pos, h.pos.size() * sizeof(double)) &&
                        engine.pin_host(rad, h.rad.size() * sizeof(double));
    if (path.pinned && !pinned) std::printf("(%s: the driver refused to page-lock the scene)\n", path.name);
    for (int r = 0; r < runs + 2; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      const cg::Contacts<float> c = engine.detect(v);
      const double ms =
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      if (r < 2) continue;  // warm-up: the workspace and the pinned ring are allocated
      total.push_back(ms);
      for (const auto& st : engine.times()) {
        if (!stage_ms.count(st.name)) stage_names.push_back(st.name);
        stage_ms[st.name].push_back(st.seconds * 1e3);
      }
      row.contacts = c.size();
      row.down_bytes =
          double(c.size()) * (2 * sizeof(c.id_a[0]) + 3 * sizeof(c.normal_on_b[0]) + sizeof(float));
    }
    if (pinned) {
      engine.unpin_host(pos);
      engine.unpin_host(rad);
    }
    // the packed path uploads 16 bytes a sphere (sphere scenes; shape scenes keep the doubles)
    const bool packed = path.host_path && std::string(path.host_path) == "packed";
    const double per_body = packed && h.shape.empty() ? 16.0 : 32.0;
    row.up_bytes = double(n) * per_body + (h.shape.empty() ? 0.0 : double(n) * (sizeof(cg::Shape) + 56));
    row.total_ms = median(total);
    row.upload_ms = median(stage_ms["upload"]);
    row.download_ms = median(stage_ms["download"]);
    std::ostringstream line;
    line << std::fixed << std::setprecision(3);
    double stage_sum = 0;
    for (const std::string& name : stage_names) {
      stage_sum += median(stage_ms[name]);
      line << name << ' ' << median(stage_ms[name]) << ", ";
    }
    line << "sum " << stage_sum << ", wall - sum " << row.total_ms - stage_sum;
    row.stages = line.str();
    row.bytes_floor_ms = row.up_bytes / (bw.h2d * 1e6) + row.down_bytes / (bw.d2h * 1e6);
    row.floor_ms = row.bytes_floor_ms + resident_ms;
    rows.push_back(row);
  }
  for (const char* k : knobs) ::unsetenv(k);
  return rows;
}

}  // namespace

int main(int argc, char** argv) try {
  // usage: contactgrid_cuda_bench [lo 16] [hi 26] [step 2] [runs 20] [cell: auto | min | edge] [scene]
  const std::string cell = argc > 5 ? argv[5] : "auto";
  const std::string scene_name = argc > 6 ? argv[6] : "spheres";
  const SceneKind kind = scene_name == "ellipsoids" ? SceneKind::ellipsoids
                         : scene_name == "mixed"    ? SceneKind::mixed
                         : scene_name == "spheres"
                             ? SceneKind::spheres
                             : throw std::runtime_error("scene: spheres, ellipsoids or mixed");
  if (cell == "min")
    g_cell_choice = cg::CellChoice::smallest;
  else if (cell != "auto")
    g_cell_size = std::atof(cell.c_str());
  const int lo = argc > 1 ? std::atoi(argv[1]) : 16;
  const int hi = argc > 2 ? std::atoi(argv[2]) : 26;
  const int step = argc > 3 ? std::atoi(argv[3]) : 2;
  const int runs = argc > 4 ? std::atoi(argv[4]) : 20;
  const double skin = argc > 7 ? std::atof(argv[7]) : 0.0;
  cudaDeviceProp prop{};
  CG_CUDA_CHECK(cudaGetDeviceProperties(&prop, 0));
  std::printf(
      "# contactgrid_cuda_bench on %s (%d SMs, %.1f GiB), median of %d warm runs, L2 flushed, cell %s, "
      "scene %s\n",
      prop.name, prop.multiProcessorCount, prop.totalGlobalMem / double(1 << 30), runs, cell.c_str(),
      scene_name.c_str());
  double scale = 1.0;  // L factor; shape scenes: calibrated to 0.4 contacts per body
  if (kind != SceneKind::spheres) {
    for (int it = 0; it < 3; ++it) {
      const double c = contacts_per_body(kind, scale);
      std::printf("# calibration: L scale %.5f -> %.4f contacts/N\n", scale, c);
      if (it < 2) scale *= std::cbrt(c / 0.4);
    }
  }
  Flusher flush;
  std::vector<Row> rows;
  std::vector<SkinRow> skin_rows;
  std::vector<HostPathRow> host_rows;
  const PinnedBandwidth bw = pinned_bandwidth();
  for (int p = lo; p <= hi; p += step) {
    const std::uint64_t n = std::uint64_t(1) << p;
    const HostScene h = make_scene(kind, n, scale, 0x5EED0000ull + p);
    DeviceScene d;
    std::vector<double> up;  // input upload (positions, radii, shape rows) from pageable memory
    for (int r = 0; r < 3; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      upload(d.pos, h.pos), upload(d.rad, h.rad), upload(d.semi, h.semi), upload(d.quat, h.quat);
      upload(d.shape, h.shape);
      up.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    }
    d.upload_ms = median(up);
    rows.push_back(bench<float>(p, n, d, runs, flush));
    for (const HostPathRow& r : bench_host_path(p, h, std::min(runs, 10), bw, rows.back().total_ms))
      host_rows.push_back(r);
    rows.push_back(bench<double>(p, n, d, runs, flush, true));
    rows.push_back(bench<double>(p, n, d, runs, flush));
    if (skin > 0) {
      skin_rows.push_back(bench_skin<float>(p, n, d, skin, runs));
      skin_rows.push_back(bench_skin<double>(p, n, d, skin, runs));
    }
    std::fprintf(stderr, "done 2^%d\n", p);
  }
  std::printf(
      "\n| N | prec | cell | entries/N | key bits | pack | entries | sort | pairs | order | narrow | GPU sum "
      "| "
      "total | "
      "Mspheres/s | contacts/N | workspace B/N | excl. contacts B/N | sort floor | sort/floor | total/floor "
      "| upload | download | candidates/N | fallbacks | unconverged | narrow: triage | narrow: settle | "
      "narrow: hard | unsettled/N | hard/N | solver runs/N | evaluations/run | max evaluations |\n");
  std::printf(
      "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
      "---|---|---|---|---|---|---|---|---|\n");
  for (const Row& r : rows) {
    auto st = [&](const char* s) {
      auto it = r.stage_ms.find(s);
      return it == r.stage_ms.end() ? 0.0 : it->second;
    };
    std::printf(
        "| 2^%d | %s | %.3g | %.2f | %d | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f | "
        "%.0f | "
        "%.3f | "
        "%.1f | %.1f | "
        "%.3f | %.2f | %.2f | %.2f | %.2f | %.3f | %llu | %llu | %.3f | %.3f | %.3f | %.4f | %.4f | %.3f | "
        "%.2f | %llu |\n",
        r.log2n, r.prec, r.cell, double(r.entries) / double(r.n), r.key_bits, st("pack"), st("entries"),
        st("sort"), st("pairs"), st("order"), st("narrow"), r.gpu_sum_ms, st("plan"), r.total_ms,
        double(r.n) / (r.total_ms * 1e-3) / 1e6, double(r.contacts) / double(r.n), r.bytes_per_sphere,
        r.bytes_no_contacts, r.floor_ms, r.floor_ms > 0 ? st("sort") / r.floor_ms : 0.0,
        r.floor_ms > 0 ? r.total_ms / r.floor_ms : 0.0, r.upload_ms, r.download_ms,
        double(r.candidates) / double(r.n), static_cast<unsigned long long>(r.fallbacks),
        static_cast<unsigned long long>(r.unconverged), st("triage"), st("settle"), st("hard"),
        double(r.unsettled) / double(r.n), double(r.hard) / double(r.n), double(r.solver_runs) / double(r.n),
        r.solver_runs ? double(r.evaluations) / double(r.solver_runs) : 0.0,
        static_cast<unsigned long long>(r.max_evaluations));
  }
  std::printf(
      "\nAll times in ms. workspace B/N = device bytes held by the engine / N, including the contact "
      "output buffer, excluding the caller's input arrays (32 B/N; shape scenes 89 B/N). fallbacks, "
      "unconverged: narrow-phase solver flags summed over the timed runs. plan = host wall time before the "
      "first stage (device bounds and shape check, each read back, and the grid plan). total = wall time of "
      "detect_device_resident (plan, stages, host syncs).\n");
  std::printf(
      "\nHost arrays -> host contacts, fp32, basic fields, one engine reused (Engine::detect), median of up "
      "to "
      "10 warm calls; pinned bandwidth here %.1f GB/s up, %.1f GB/s down. bytes floor = bytes up / "
      "bandwidth up + bytes down / bandwidth down (the row's own bytes: packed 16 B a sphere up, the others "
      "32); "
      "floor = bytes floor + the device-resident total above.\n\n| N | transfer | contacts | MB up | "
      "MB down | upload | download | total | bytes floor | total/bytes floor | floor | total/floor "
      "|\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
      bw.h2d, bw.d2h);
  for (const HostPathRow& r : host_rows)
    std::printf("| 2^%d | %s | %llu | %.1f | %.1f | %.3f | %.3f | %.3f | %.3f | %.2f | %.3f | %.2f |\n",
                r.log2n, r.transfer, static_cast<unsigned long long>(r.contacts), r.up_bytes / 1e6,
                r.down_bytes / 1e6, r.upload_ms, r.download_ms, r.total_ms, r.bytes_floor_ms,
                r.total_ms / r.bytes_floor_ms, r.floor_ms, r.total_ms / r.floor_ms);
  std::printf(
      "\nHost path stages (ms, medians; plan on the host's clock, the rest CUDA events; wall - sum: "
      "what no stage holds):\n\n");
  for (const HostPathRow& r : host_rows)
    std::printf("- 2^%d %s: %s\n", r.log2n, r.transfer, r.stages.c_str());
  if (!skin_rows.empty()) {
    std::printf(
        "\nSteps with a skin of %g (moves <= skin/10 per step, %d steps; wall ms per step of "
        "detect_device_resident):\n\n| N | prec | from scratch | skin: reuse | skin: rebuild | "
        "skin: mean | builds | reuses | same counts |\n|---|---|---|---|---|---|---|---|---|\n",
        skin, runs);
    for (const SkinRow& r : skin_rows)
      std::printf("| 2^%d | %s | %.3f | %.3f | %.3f | %.3f | %llu | %llu | %s |\n", r.log2n, r.prec,
                  r.scratch_ms, r.reuse_ms, r.build_ms, r.mean_ms, static_cast<unsigned long long>(r.builds),
                  static_cast<unsigned long long>(r.reuses), r.same ? "yes" : "NO");
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "contactgrid_cuda_bench: %s\n", e.what());
  return 1;
}
