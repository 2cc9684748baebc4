// The CPU backend: Le Grand's stages on OpenMP threads, over the same core math as the CUDA kernels.
// It is the laptop mode and the oracle for the CUDA backend: every decision (cells, pair rule,
// contact test) and every contact value is computed by the same CG_HD functions in the same order.
//
// Stages (names as in the timing table):
//   pack      world (double) → local frame Real spheres; per body: cells, entry count, control byte
//   entries   exclusive scan of entry counts → fill (cell key, body) entries in body order
//   sort      stable radix sort of the entries by cell key over plan.key_bits bits
//   pairs     per entry: tests against later entries of its cell (cells of type 0 first: Le Grand's
//             8 passes); contacting pairs (a < b, local indices) collected per chunk of entries,
//             then chunk sizes → scan → fill
//   order     radix sort of the pairs by (a, b)
//   narrow    contact data for each pair, in the requested fields, world frame
#include <omp.h>

#include <chrono>
#include <numeric>
#include <vector>

#include "backend.hpp"
#include "core/contact.hpp"
#include "core/grid.hpp"
#include "host/radix_sort.hpp"

namespace cg::detail {
namespace {

using clock_type = std::chrono::steady_clock;

// Below this many items a loop runs on the calling thread: waking a team costs more than it saves.
constexpr std::size_t k_parallel_min = 32768;

class StageTimer {
 public:
  explicit StageTimer(StageTimes& times) : m_times(times), m_t(clock_type::now()) {}
  void lap(const char* name) {
    auto now = clock_type::now();
    m_times.push_back({name, std::chrono::duration<double>(now - m_t).count()});
    m_t = now;
  }

 private:
  StageTimes& m_times;
  clock_type::time_point m_t;
};

// Exclusive scan in place; returns the total.
template <class T, class Acc>
Acc exclusive_scan_inplace(std::vector<T>& counts, std::vector<Acc>& offsets) {
  offsets.resize(counts.size() + 1);
  Acc sum = 0;
  for (std::size_t i = 0; i < counts.size(); ++i) {
    offsets[i] = sum;
    sum += counts[i];
  }
  offsets[counts.size()] = sum;
  return sum;
}

template <class Real, class Key>
void run_typed(const HostBackend& be, const DetectJob<Real>& job, Contacts<Real>& out, StageTimes& times,
               EngineStats& stats) {
  const int nt = be.threads > 0 ? be.threads : omp_get_max_threads();
  const std::size_t n = job.bodies.size();
  const GridParams<Real> g = job.grid;
  const Vec3<double> origin = job.plan.frame.origin;
  StageTimer timer(times);

  // pack
  std::vector<Sphere<Real>> spheres(n);
  std::vector<BodyCells> cells(n);
  std::vector<std::uint8_t> ctrl(n);
  std::vector<std::uint32_t> count(n);
#pragma omp parallel for num_threads(nt) schedule(static) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3<double> p = job.bodies.position[i];
    Sphere<Real> s{static_cast<Real>(p.x - origin.x), static_cast<Real>(p.y - origin.y),
                   static_cast<Real>(p.z - origin.z), static_cast<Real>(job.bodies.radius[i])};
    spheres[i] = s;
    cells[i] = body_cells(s, g);
    ctrl[i] = control_bits(cells[i]);
    count[i] = entry_count(cells[i]);
  }
  timer.lap("pack");

  // entries: count → scan → fill
  std::vector<std::uint64_t> offset;
  const std::uint64_t n_entries = exclusive_scan_inplace(count, offset);
  std::vector<Key> keys(n_entries);
  std::vector<std::uint32_t> body(n_entries);
#pragma omp parallel for num_threads(nt) schedule(static) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    for (std::uint32_t m = 0; m < count[i]; ++m) {
      keys[offset[i] + m] = body_cell_key<Key>(cells[i], m, g);
      body[offset[i] + m] = static_cast<std::uint32_t>(i);
    }
  }
  cells = {};
  count = {};
  offset = {};
  stats.entries = n_entries;
  timer.lap("entries");

  radix_sort(keys, body, job.plan.key_bits, nt);
  timer.lap("sort");

  // pairs: count → scan → fill. Entry e tests the later entries f of its cell; within a cell the
  // bodies ascend (stable sort of entries made in body order), so body[e] < body[f]. The spheres and
  // control bytes are first gathered into entry order, so both passes below read memory in sequence.
  std::vector<Sphere<Real>> entry_sphere(n_entries);
  std::vector<std::uint8_t> entry_ctrl(n_entries);
#pragma omp parallel for num_threads(nt) schedule(static) if (n_entries > k_parallel_min)
  for (std::size_t e = 0; e < n_entries; ++e) {
    entry_sphere[e] = spheres[body[e]];
    entry_ctrl[e] = ctrl[body[e]];
  }
  const bool all = job.bodies.report.empty();
  const std::uint8_t* report = job.bodies.report.data();
  const int half_bits = g.half_bits;
  auto for_each_contact = [&](std::size_t e, auto&& emit) {
    const Key k = keys[e];
    const std::uint32_t a = body[e];
    if (!all && !(report[a] & kReportedBit)) return std::uint64_t(0);  // pairs (a, b > a) belong to a's owner
    const std::uint32_t type = key_type(k, half_bits);
    const Sphere<Real> sa = entry_sphere[e];
    const std::uint8_t ca = entry_ctrl[e];
    std::uint64_t tests = 0;
    const std::uint8_t pa = all ? 0 : report[a];
    for (std::size_t f = e + 1; f < n_entries && keys[f] == k; ++f) {
      if ((pa & kPairedBit) && (report[body[f]] & kPairedBit)) continue;  // both paired elsewhere
      if (!test_in_cell(ca, entry_ctrl[f], type)) continue;
      ++tests;
      if (spheres_touch(sa, entry_sphere[f])) emit(a, body[f]);
    }
    return tests;
  };
  // count → scan → fill at the granularity of fixed chunks of entries: each chunk collects its pairs
  // once (no second walk of the cells), the chunk sizes are scanned, the chunks copied in order. The
  // chunking depends only on the entry count, so the pair array is the same for any thread count.
  const int id_bits = std::max(1, bits_for(n));
  const std::size_t n_chunks = std::max<std::size_t>(1, std::min<std::size_t>(256, n_entries / 16384));
  std::vector<std::vector<std::uint64_t>> chunk_pairs(n_chunks);
  std::uint64_t tests_total = 0;
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1) reduction(+ : tests_total) if (n_chunks > 1)
  for (std::size_t c = 0; c < n_chunks; ++c) {
    std::vector<std::uint64_t>& mine = chunk_pairs[c];
    for (std::size_t e = n_entries * c / n_chunks, end = n_entries * (c + 1) / n_chunks; e < end; ++e)
      tests_total += for_each_contact(
          e, [&](std::uint32_t a, std::uint32_t b) { mine.push_back((std::uint64_t(a) << id_bits) | b); });
  }
  std::vector<std::uint64_t> chunk_size(n_chunks), chunk_offset;
  for (std::size_t c = 0; c < n_chunks; ++c) chunk_size[c] = chunk_pairs[c].size();
  const std::uint64_t n_pairs = exclusive_scan_inplace(chunk_size, chunk_offset);
  std::vector<std::uint64_t> pairs(n_pairs);
#pragma omp parallel for num_threads(nt) schedule(static) if (n_chunks > 1)
  for (std::size_t c = 0; c < n_chunks; ++c) {
    std::copy(chunk_pairs[c].begin(), chunk_pairs[c].end(), pairs.begin() + std::ptrdiff_t(chunk_offset[c]));
    chunk_pairs[c] = {};
  }
  entry_sphere = {};
  entry_ctrl = {};
  stats.pair_tests = tests_total;
  timer.lap("pairs");

  radix_sort_keys(pairs, 2 * id_bits, nt);
  timer.lap("order");

  // narrow phase over the sorted pairs
  const bool full = job.fields == Fields::full;
  out.resize(n_pairs, full);
  const std::uint64_t id_mask = (std::uint64_t(1) << id_bits) - 1;
#pragma omp parallel for num_threads(nt) schedule(static) if (n_pairs > k_parallel_min)
  for (std::size_t k = 0; k < n_pairs; ++k) {
    const std::uint32_t a = static_cast<std::uint32_t>(pairs[k] >> id_bits);
    const std::uint32_t b = static_cast<std::uint32_t>(pairs[k] & id_mask);
    const ContactRow<Real> row = sphere_contact_row(spheres[a], spheres[b], origin, full);
    out.id_a[k] = a;
    out.id_b[k] = b;
    out.position_on_a[k] = row.position_on_a;
    out.position_on_b[k] = row.position_on_b;
    out.normal_on_b[k] = row.normal_on_b;
    out.distance[k] = row.distance;
    if (full) {
      out.local_point_a[k] = row.local_point_a;
      out.local_point_b[k] = row.local_point_b;
      out.lateral_friction_dir1[k] = row.lateral_friction_dir1;
      out.lateral_friction_dir2[k] = row.lateral_friction_dir2;
    }
  }
  timer.lap("narrow");
}

}  // namespace

template <class Real>
void run_stages(HostBackend& backend, const DetectJob<Real>& job, Contacts<Real>& out, StageTimes& times,
                EngineStats& stats) {
  if (job.bodies.size() >= (std::size_t(1) << 32))
    throw InputError("more than 2^32 - 1 bodies on one rank; use more MPI ranks");
  if (job.plan.key64)
    run_typed<Real, std::uint64_t>(backend, job, out, times, stats);
  else
    run_typed<Real, std::uint32_t>(backend, job, out, times, stats);
}

template void run_stages(HostBackend&, const DetectJob<float>&, Contacts<float>&, StageTimes&, EngineStats&);
template void run_stages(HostBackend&, const DetectJob<double>&, Contacts<double>&, StageTimes&,
                         EngineStats&);

}  // namespace cg::detail
