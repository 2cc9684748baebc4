// Host stage pairs: the candidate pairs of the sorted entries (see stages.hpp).
#include <algorithm>
#include <atomic>
#include <functional>

#include "backend.hpp"
#include "host/stages.hpp"

namespace cg::detail::host {
namespace {

// Entry e tests the later entries f of its cell; within a cell the bodies ascend (stable sort of
// entries made in body order), so body[e] < body[f]. `test`: the candidate filter's pair test
// (core/narrow.hpp: SpheresTouch, CellRule, or mixed's Fp64Touch; core/centre_cut.hpp: CentreCut), on
// input indices.
template <class Test, class Real, class Key, class Emit>
std::uint64_t walk_entry(std::size_t e, const Entries<Key>& en, const Sphere<Real>* entry_sphere,
                         const std::uint8_t* entry_ctrl, const std::uint8_t* report, int half_bits,
                         const Test& test, Emit&& emit) {
  const std::size_t n_entries = en.size();
  const Key k = en.keys[e];
  const std::uint32_t a = en.body[e];
  // pairs (a, b > a) belong to a's owner, but a wide a's with narrow bodies to theirs (pair_reported)
  if (report && !(report[a] & (kReportedBit | kWideBit))) return 0;
  const std::uint32_t type = key_type(k, half_bits);
  const Sphere<Real> sa = entry_sphere[e];
  const std::uint8_t ca = entry_ctrl[e];
  std::uint64_t tests = 0;
  for (std::size_t f = e + 1; f < n_entries && en.keys[f] == k; ++f) {
    if (report && !pair_reported(report, a, en.body[f])) continue;
    if (!test_in_cell(ca, entry_ctrl[f], type)) continue;
    ++tests;
    if (test(sa, entry_sphere[f], a, en.body[f])) emit(a, en.body[f]);
  }
  return tests;
}

// The pair stage's progress (PairLimits::on_progress): each thread adds its tests every kStep of them;
// whichever thread gets the flag reports the sum, so the callback runs on one thread at a time.
class ProgressShare {
 public:
  static constexpr std::uint64_t kStep = std::uint64_t(1) << 24;
  explicit ProgressShare(const std::function<void(std::uint64_t, bool)>* report) : m_report(report) {}
  bool on() const { return m_report != nullptr; }
  void add(std::uint64_t tests) {
    const std::uint64_t done = m_done.fetch_add(tests, std::memory_order_relaxed) + tests;
    if (m_busy.test_and_set(std::memory_order_acquire)) return;
    (*m_report)(done, false);
    m_busy.clear(std::memory_order_release);
  }
  void finish() {
    if (on()) (*m_report)(m_done.load(), true);
  }

 private:
  const std::function<void(std::uint64_t, bool)>* m_report;
  std::atomic<std::uint64_t> m_done{0};
  std::atomic_flag m_busy = ATOMIC_FLAG_INIT;
};

template <class Test, class Real, class Key>
std::uint64_t collect(const Entries<Key>& en, const PackedBodies<Real>& p, const std::uint8_t* report,
                      int half_bits, int nt, const Test& test, CandidatePairs& out, ProgressShare& progress) {
  const std::size_t n_entries = en.size();
  // The spheres (inflated by a skin) and control bytes are first gathered into entry order, so the
  // walk reads memory in sequence.
  Array<Sphere<Real>> entry_sphere(n_entries);
  Array<std::uint8_t> entry_ctrl(n_entries);
#pragma omp parallel for num_threads(nt) schedule(static) if (n_entries > k_parallel_min)
  for (std::size_t e = 0; e < n_entries; ++e) {
    entry_sphere[e] = p.spheres[en.body[e]];
    entry_sphere[e].r += p.inflation;  // a skin: the inflated spheres (0: exactly r)
    entry_ctrl[e] = p.ctrl[en.body[e]];
  }
  // count → scan → fill at the granularity of fixed chunks of entries: each chunk collects its pairs
  // once (no second walk of the cells), the chunk sizes are scanned, the chunks copied in order. The
  // chunking depends only on the entry count, so the pair array is the same for any thread count.
  const int id_bits = out.id_bits;
  const std::size_t n_chunks = std::max<std::size_t>(1, std::min<std::size_t>(256, n_entries / 16384));
  std::vector<std::vector<std::uint64_t>> chunk_pairs(n_chunks);
  std::uint64_t tests_total = 0;
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1) reduction(+ : tests_total) if (n_chunks > 1)
  for (std::size_t c = 0; c < n_chunks; ++c) {
    std::vector<std::uint64_t>& mine = chunk_pairs[c];
    std::uint64_t unreported = 0;
    for (std::size_t e = n_entries * c / n_chunks, end = n_entries * (c + 1) / n_chunks; e < end; ++e) {
      const std::uint64_t tests = walk_entry(
          e, en, entry_sphere.data(), entry_ctrl.data(), report, half_bits, test,
          [&](std::uint32_t a, std::uint32_t b) { mine.push_back((std::uint64_t(a) << id_bits) | b); });
      tests_total += tests;
      unreported += tests;
      if (progress.on() && unreported >= ProgressShare::kStep) {
        progress.add(unreported);
        unreported = 0;
      }
    }
    if (progress.on() && unreported > 0) progress.add(unreported);
  }
  progress.finish();
  std::vector<std::uint64_t> chunk_size(n_chunks), chunk_offset;
  for (std::size_t c = 0; c < n_chunks; ++c) chunk_size[c] = chunk_pairs[c].size();
  const std::uint64_t n_pairs = exclusive_scan_into(chunk_size, chunk_offset);
  out.ab.resize(n_pairs);
#pragma omp parallel for num_threads(nt) schedule(static) if (n_chunks > 1)
  for (std::size_t c = 0; c < n_chunks; ++c) {
    std::copy(chunk_pairs[c].begin(), chunk_pairs[c].end(), out.ab.begin() + std::ptrdiff_t(chunk_offset[c]));
    chunk_pairs[c] = {};
  }
  return tests_total;
}

}  // namespace

template <class Key>
PairEstimate estimate_pair_tests(const Entries<Key>& en, std::uint64_t bodies, int threads) {
  const std::size_t n = en.size();
  const Key* keys = en.keys.data();
  const std::size_t n_chunks = std::max<std::size_t>(1, std::min<std::size_t>(256, n / 16384));
  std::uint64_t tests = 0, largest = 0;
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1) reduction(+ : tests) \
    reduction(max : largest) if (n_chunks > 1)
  for (std::size_t c = 0; c < n_chunks; ++c) {
    const std::size_t end = n * (c + 1) / n_chunks;
    std::size_t e = n * c / n_chunks;
    while (e > 0 && e < end && keys[e] == keys[e - 1]) ++e;  // that cell is the earlier chunk's
    while (e < end) {
      std::size_t f = e + 1;
      while (f < n && keys[f] == keys[e]) ++f;
      const std::uint64_t m = f - e;
      tests += m * (m - 1) / 2;
      largest = std::max(largest, m);
      e = f;
    }
  }
  return {tests, bodies, n, largest};
}

template PairEstimate estimate_pair_tests(const Entries<std::uint32_t>&, std::uint64_t, int);
template PairEstimate estimate_pair_tests(const Entries<std::uint64_t>&, std::uint64_t, int);

template <class Real, class Key>
std::uint64_t find_candidates(const Entries<Key>& e, const PackedBodies<Real>& p,
                              std::span<const std::uint8_t> report, int half_bits, CandidateFilter filter,
                              const NarrowBodies<double>* fp64, int threads, CandidatePairs& out,
                              const std::function<void(std::uint64_t, bool)>* on_progress) {
  ProgressShare progress(on_progress);
  out.id_bits = std::max(1, bits_for(p.spheres.size()));
  out.filter = filter;
  const std::uint8_t* r = report.empty() ? nullptr : report.data();
  return with_pair_test(filter, p, fp64, [&](const auto& test) {
    return collect(e, p, r, half_bits, threads, test, out, progress);
  });
}

template std::uint64_t find_candidates(const Entries<std::uint32_t>&, const PackedBodies<float>&,
                                       std::span<const std::uint8_t>, int, CandidateFilter,
                                       const NarrowBodies<double>*, int, CandidatePairs&,
                                       const std::function<void(std::uint64_t, bool)>*);
template std::uint64_t find_candidates(const Entries<std::uint64_t>&, const PackedBodies<float>&,
                                       std::span<const std::uint8_t>, int, CandidateFilter,
                                       const NarrowBodies<double>*, int, CandidatePairs&,
                                       const std::function<void(std::uint64_t, bool)>*);
template std::uint64_t find_candidates(const Entries<std::uint32_t>&, const PackedBodies<double>&,
                                       std::span<const std::uint8_t>, int, CandidateFilter,
                                       const NarrowBodies<double>*, int, CandidatePairs&,
                                       const std::function<void(std::uint64_t, bool)>*);
template std::uint64_t find_candidates(const Entries<std::uint64_t>&, const PackedBodies<double>&,
                                       std::span<const std::uint8_t>, int, CandidateFilter,
                                       const NarrowBodies<double>*, int, CandidatePairs&,
                                       const std::function<void(std::uint64_t, bool)>*);

}  // namespace cg::detail::host
