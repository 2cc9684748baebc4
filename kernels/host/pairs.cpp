// Host stage pairs: the candidate pairs of the sorted entries (see stages.hpp).
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define CG_HOST_AVX2 1
#endif

#include <algorithm>
#include <cstdlib>
#include <functional>
#include <string_view>
#include <type_traits>

#include "backend.hpp"
#include "host/pair_walk.hpp"
#include "host/stages.hpp"

namespace cg::detail::host {
namespace {

// How the float walk without a report mask steps over a cell's later entries; every way makes the
// same tests, counts the same and emits the same pairs in the same order.
//   flags: 128 later entries flagged at a time (plain C++, what the compiler vectorises)
//   sse:   four later entries a step as bit masks (SSE2)
//   avx2:  eight later entries a step (AVX2, chosen at run time where the CPU has it); an entry with at
//          most eight later entries in its cell (most) takes one step, and its cell's lanes are loaded
//          once for all its entries; the pairs the bound keeps are tested after the cell, in order
// CONTACTGRID_HOST_WALK=flags|sse|avx2 picks one (read each call: a measurement switch and the tests'
// way to compare them); unset, avx2 where the CPU has it, else sse. avx2 on a CPU without it: sse.
enum class WalkKind { flags, sse, avx2 };

bool cpu_has_avx2() {
#if defined(CG_HOST_AVX2)
  static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("popcnt");
  return has;
#else
  return false;
#endif
}

WalkKind walk_kind() {
  const char* k = std::getenv("CONTACTGRID_HOST_WALK");
  const std::string_view v = k != nullptr ? std::string_view(k) : std::string_view();
  if (v == "flags") return WalkKind::flags;
#if defined(__SSE2__)
  if (v == "sse" || !cpu_has_avx2()) return WalkKind::sse;
  return WalkKind::avx2;
#else
  return WalkKind::flags;
#endif
}

// The pair (a, b) of entries e and f of one cell, tested and emitted as (lower body, higher body): the
// cell sort (host/cell_sort.cpp) leaves a cell's entries in no body order, and every test is called
// with the lower input index first, as on the body-ascending cells of the entry sort.
template <class Test, class Real, class Emit>
inline void test_ordered(const Test& test, const Sphere<Real>& se, std::uint32_t a, const Sphere<Real>& sf,
                         std::uint32_t b, Emit& emit) {
  if (a < b) {
    if (test(se, sf, a, b)) emit(a, b);
  } else if (test(sf, se, b, a)) {
    emit(b, a);
  }
}

#if defined(CG_HOST_AVX2)
// Eight later entries of a cell (lanes j: entries first + j), structure of arrays.
struct Lanes8 {
  __m256 x, y, z, r;
  __m256i ctrl;
};

__attribute__((target("avx2"))) inline Lanes8 load8(const EntryBodies<float>& eb, std::size_t first) {
  return {_mm256_loadu_ps(eb.x.data() + first), _mm256_loadu_ps(eb.y.data() + first),
          _mm256_loadu_ps(eb.z.data() + first), _mm256_loadu_ps(eb.r.data() + first),
          _mm256_loadu_si256(reinterpret_cast<const __m256i*>(eb.ctrl.data() + first))};
}

// Entry e (sphere a, control byte ca, a_two = its test_in_cell bits) against eight lanes: `assigned`
// the lanes whose pair the cell rule assigns to this cell, `near` those within NearBound's distance —
// the arithmetic of the flag loop and the four-lane step, lane by lane (no FMA: every rounding the same).
__attribute__((target("avx2"))) inline void step8(const Lanes8& l, const Sphere<float>& a, std::uint32_t ca,
                                                  std::uint32_t a_two, __m256 margin2, unsigned& assigned,
                                                  unsigned& near) {
  const __m256i two = _mm256_and_si256(_mm256_set1_epi32(int(a_two)), _mm256_srli_epi32(l.ctrl, 3));
  const __m256i rule = _mm256_cmpeq_epi32(
      _mm256_andnot_si256(_mm256_xor_si256(_mm256_set1_epi32(int(ca)), l.ctrl), two), _mm256_setzero_si256());
  assigned = unsigned(_mm256_movemask_ps(_mm256_castsi256_ps(rule)));
  const __m256 dx = _mm256_sub_ps(_mm256_set1_ps(a.x), l.x);
  const __m256 dy = _mm256_sub_ps(_mm256_set1_ps(a.y), l.y);
  const __m256 dz = _mm256_sub_ps(_mm256_set1_ps(a.z), l.z);
  const __m256 d2 =
      _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)), _mm256_mul_ps(dz, dz));
  const __m256 sum = _mm256_add_ps(_mm256_add_ps(_mm256_set1_ps(a.r), l.r), margin2);
  near = unsigned(_mm256_movemask_ps(_mm256_cmp_ps(d2, _mm256_mul_ps(sum, sum), _CMP_LE_OQ)));
}

// A step's lanes that the bound keeps (entry e against entries first + j): tested after the cell.
struct PendingStep {
  std::size_t e, first;
  unsigned lanes;
};

// walk_entries' float walk without a report mask in AVX2 (WalkKind::avx2): the same tests, count and
// emitted pairs in the same order. A cell whose entries from e on number at most nine loads its lanes
// once, and each of its entries takes one step (lanes after its own place); a longer cell steps each
// entry over its later entries eight at a time. The kept lanes are queued (no branch on them in the
// step) and tested in order when the queue fills and at the end.
template <class Test, class Key, class Emit>
__attribute__((target("avx2,popcnt"))) std::uint64_t walk_avx2(std::size_t lo, std::size_t hi,
                                                               const Entries<Key>& en,
                                                               const EntryBodies<float>& eb, int half_bits,
                                                               const Test& test, Emit& emit) {
  const std::size_t n_entries = en.size();
  const Key* keys = en.keys.data();
  const std::uint32_t* body = en.body.data();
  const std::uint32_t* ec = eb.ctrl.data();
  const NearBound<Test, float> near_bound(test);
  const __m256 margin2 = _mm256_set1_ps(near_bound.margin2);
  const unsigned near_all = near_bound.all ? 0xffu : 0u;
  constexpr std::size_t k_pending = 256;
  PendingStep pending[k_pending];
  std::size_t n_pending = 0;
  const auto flush = [&] {
    for (std::size_t k = 0; k < n_pending; ++k) {
      const PendingStep& q = pending[k];
      const std::uint32_t a = body[q.e];
      const Sphere<float> sa = eb.sphere(q.e);
      for (unsigned w = q.lanes; w != 0; w &= w - 1) {
        const std::size_t f = q.first + std::size_t(__builtin_ctz(w));
        test_ordered(test, sa, a, eb.sphere(f), body[f], emit);
      }
    }
    n_pending = 0;
  };
  std::uint64_t tests = 0;
  for (std::size_t e = lo; e < hi;) {
    std::size_t cell_end = e + 1;  // entry e starts a cell, or the chunk starts inside one
    while (cell_end < n_entries && keys[cell_end] == keys[e]) ++cell_end;
    const std::uint32_t type = key_type(keys[e], half_bits);
    const std::size_t stop = std::min(hi, cell_end);
    if (cell_end - e == 1) {  // a lone entry: no later ones
      e = stop;
      continue;
    }
    if (cell_end - e <= 9) {  // lanes j: entries e + 1 + j; entry e + p takes lanes p … of the cell
      if (n_pending + 9 > k_pending) flush();  // each of its (at most nine) entries writes a slot
      const Lanes8 l = load8(eb, e + 1);
      const unsigned cell = (1u << (cell_end - e - 1)) - 1u;
      for (std::size_t p = 0; e + p < stop; ++p) {
        const std::size_t ep = e + p;
        const std::uint32_t ca = ec[ep];
        unsigned assigned, near;
        step8(l, eb.sphere(ep), ca, (ca >> 3) & type, margin2, assigned, near);
        assigned &= cell & (0xffu << p);
        tests += unsigned(__builtin_popcount(assigned));
        pending[n_pending] = {ep, e + 1, assigned & (near | near_all)};
        n_pending += pending[n_pending].lanes != 0;
      }
    } else {
      for (std::size_t ep = e; ep < stop; ++ep) {
        const std::uint32_t ca = ec[ep];
        const Sphere<float> sa = eb.sphere(ep);
        for (std::size_t first = ep + 1; first < cell_end; first += 8) {
          if (n_pending == k_pending) flush();
          const unsigned lanes = cell_end - first >= 8 ? 0xffu : (1u << (cell_end - first)) - 1u;
          unsigned assigned, near;
          step8(load8(eb, first), sa, ca, (ca >> 3) & type, margin2, assigned, near);
          assigned &= lanes;
          tests += unsigned(__builtin_popcount(assigned));
          pending[n_pending] = {ep, first, assigned & (near | near_all)};
          n_pending += pending[n_pending].lanes != 0;
        }
      }
    }
    e = stop;
  }
  flush();
  return tests;
}
#endif

// Entries [lo, hi) of the walk: entry e tests the later entries f of its cell; within a cell the
// bodies ascend after the entry sort (stable, of entries made in body order), but not after the cell
// sort, so each pair is tested as (lower body, higher body) (test_ordered); the report mask's walk
// takes only the entry sort's cells, where body[e] < body[f]. `test`: the
// candidate filter's pair test (core/narrow.hpp: SpheresTouch, CellRule, or mixed's Fp64Touch;
// core/centre_cut.hpp: CentreCut), on input indices; it decides every pair the cell rule (and the
// report mask) assigns, less those NearBound proves it rejects. Returns the pairs tested.
template <class Test, class Real, class Key, class Emit>
std::uint64_t walk_entries(std::size_t lo, std::size_t hi, const Entries<Key>& en,
                           const EntryBodies<Real>& eb, const std::uint8_t* report, int half_bits,
                           const Test& test, WalkKind kind, Emit&& emit) {
  static_cast<void>(kind);  // (builds without SSE2: the flag loop only)
#if defined(CG_HOST_AVX2)
  if constexpr (std::is_same_v<Real, float>)
    if (kind == WalkKind::avx2 && report == nullptr) return walk_avx2(lo, hi, en, eb, half_bits, test, emit);
#endif
  const std::size_t n_entries = en.size();
  const Key* keys = en.keys.data();
  const std::uint32_t* body = en.body.data();
  const Real *ex = eb.x.data(), *ey = eb.y.data(), *ez = eb.z.data(), *er = eb.r.data();
  const std::uint32_t* ec = eb.ctrl.data();
  const NearBound<Test, Real> near_bound(test);
  constexpr std::size_t k_block = 128;  // later entries of one cell flagged at a time
  std::uint32_t flag[k_block];
  std::uint64_t tests = 0;
  std::size_t cell_end = lo;
  for (std::size_t e = lo; e < hi; ++e) {
    if (e >= cell_end) {  // entry e starts a cell, or the chunk starts inside one
      cell_end = e + 1;
      while (cell_end < n_entries && keys[cell_end] == keys[e]) ++cell_end;
    }
    const std::uint32_t a = body[e];
    const std::uint32_t type = key_type(keys[e], half_bits);
    const std::uint32_t ca = ec[e];
    if (report) {
      // pairs (a, b > a) belong to a's owner, but a wide a's with narrow bodies to theirs (pair_reported)
      if (!(report[a] & (kReportedBit | kWideBit))) continue;
      const Sphere<Real> sa = eb.sphere(e);
      for (std::size_t f = e + 1; f < cell_end; ++f) {
        if (!pair_reported(report, a, body[f])) continue;
        if (!test_in_cell(std::uint8_t(ca), std::uint8_t(ec[f]), type)) continue;
        ++tests;
        if (test(sa, eb.sphere(f), a, body[f])) emit(a, body[f]);
      }
      continue;
    }
    const Real ax = ex[e], ay = ey[e], az = ez[e], ar = er[e];
    const std::uint32_t a_two = (ca >> 3) & type;  // test_in_cell: axes both span, whose type bit is set
#if defined(__SSE2__)
    if constexpr (std::is_same_v<Real, float>) {
      if (kind != WalkKind::flags) {  // the same rule and bound, four later entries a step, as bit masks
        const __m128 vax = _mm_set1_ps(ax), vay = _mm_set1_ps(ay), vaz = _mm_set1_ps(az),
                     var = _mm_set1_ps(ar);
        const __m128 margin2 = _mm_set1_ps(near_bound.margin2);
        const __m128i vca = _mm_set1_epi32(int(ca)), vtwo = _mm_set1_epi32(int(a_two));  // a_two: 3 bits
        const int near_all = near_bound.all ? 15 : 0;
        for (std::size_t first = e + 1; first < cell_end; first += 4) {
          const int lanes = cell_end - first >= 4 ? 15 : (1 << (cell_end - first)) - 1;  // the cell's
          const __m128i cf = _mm_loadu_si128(reinterpret_cast<const __m128i*>(ec + first));
          const __m128i two = _mm_and_si128(vtwo, _mm_srli_epi32(cf, 3));
          const __m128i rule =
              _mm_cmpeq_epi32(_mm_andnot_si128(_mm_xor_si128(vca, cf), two), _mm_setzero_si128());
          const int assigned = _mm_movemask_ps(_mm_castsi128_ps(rule)) & lanes;
          tests += (0x4332322132212110ull >> (4 * assigned)) & 15u;  // the set lanes (no popcnt in x86-64)
          const __m128 dx = _mm_sub_ps(vax, _mm_loadu_ps(ex + first));
          const __m128 dy = _mm_sub_ps(vay, _mm_loadu_ps(ey + first));
          const __m128 dz = _mm_sub_ps(vaz, _mm_loadu_ps(ez + first));
          const __m128 d2 =
              _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)), _mm_mul_ps(dz, dz));
          const __m128 sum = _mm_add_ps(_mm_add_ps(var, _mm_loadu_ps(er + first)), margin2);
          const int near = near_all | _mm_movemask_ps(_mm_cmple_ps(d2, _mm_mul_ps(sum, sum)));
          for (int wanted = assigned & near; wanted != 0; wanted &= wanted - 1) {
            const std::size_t f = first + std::size_t(__builtin_ctz(unsigned(wanted)));
            test_ordered(test, Sphere<Real>{ax, ay, az, ar}, a, eb.sphere(f), body[f], emit);
          }
        }
        continue;
      }
    }
#endif
    for (std::size_t first = e + 1; first < cell_end; first += k_block) {
      const std::size_t len = std::min(k_block, cell_end - first);
      std::uint32_t assigned = 0, wanted = 0;
      // flag bit 0: the cell rule assigns the pair here (test_in_cell); bit 1: it is near (NearBound)
      for (std::size_t j = 0; j < len; ++j) {
        const std::size_t f = first + j;
        const std::uint32_t cf = ec[f];
        const std::uint32_t rule = (~(ca ^ cf) & a_two & (cf >> 3) & 7u) == 0u;
        const Real dx = ax - ex[f], dy = ay - ey[f], dz = az - ez[f];
        const Real d2 = dx * dx + dy * dy + dz * dz;
        const Real s = (ar + er[f]) + near_bound.margin2;
        const std::uint32_t near = near_bound.all || d2 <= s * s;
        flag[j] = rule | (near << 1);
        assigned += rule;
        wanted |= rule & near;
      }
      tests += assigned;
      if (!wanted) continue;
      const Sphere<Real> sa{ax, ay, az, ar};
      for (std::size_t j = 0; j < len; ++j)
        if (flag[j] == 3u) test_ordered(test, sa, a, eb.sphere(first + j), body[first + j], emit);
    }
  }
  return tests;
}

template <class Test, class Real, class Key>
std::uint64_t collect(const Entries<Key>& en, const PackedBodies<Real>& p, const std::uint8_t* report,
                      int half_bits, int nt, const Test& test, CandidatePairs& out, ProgressShare& progress,
                      const EntryBodies<Real>* gathered) {
  const std::size_t n_entries = en.size();
  const WalkKind kind = walk_kind();
  EntryBodies<Real> own;
  if (gathered == nullptr) {
    resize_entry_bodies(own, n_entries);
    // (the bodies of a cell are random places in input order: their reads are asked for ahead)
    constexpr std::size_t ahead = 64;
#pragma omp parallel for num_threads(nt) schedule(static) if (n_entries > k_parallel_min)
    for (std::size_t e = 0; e < n_entries; ++e) {
      if (e + ahead < n_entries) {
        __builtin_prefetch(p.spheres.data() + en.body[e + ahead]);
        __builtin_prefetch(p.ctrl.data() + en.body[e + ahead]);
      }
      const std::uint32_t b = en.body[e];
      const Sphere<Real> s = p.spheres[b];
      own.x[e] = s.x;
      own.y[e] = s.y;
      own.z[e] = s.z;
      own.r[e] = s.r + p.inflation;  // a skin: the inflated spheres (0: exactly r)
      own.ctrl[e] = p.ctrl[b];
    }
  }
  const EntryBodies<Real>& eb = gathered != nullptr ? *gathered : own;
  // chunks of entries, each appending its pairs to its thread's buffer (collect_in_chunks)
  return collect_in_chunks(n_entries, nt, out, progress, [&](std::size_t begin, std::size_t end, auto& emit) {
    return walk_entries(begin, end, en, eb, report, half_bits, test, kind, emit);
  });
}

}  // namespace

bool walk_avx2_available() { return cpu_has_avx2(); }

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
                              const std::function<void(std::uint64_t, bool)>* on_progress,
                              const EntryBodies<Real>* gathered) {
  ProgressShare progress(on_progress);
  out.id_bits = std::max(1, bits_for(p.spheres.size()));
  out.filter = filter;
  const std::uint8_t* r = report.empty() ? nullptr : report.data();
  return with_pair_test(filter, p, fp64, [&](const auto& test) {
    return collect(e, p, r, half_bits, threads, test, out, progress, gathered);
  });
}

template std::uint64_t find_candidates(const Entries<std::uint32_t>&, const PackedBodies<float>&,
                                       std::span<const std::uint8_t>, int, CandidateFilter,
                                       const NarrowBodies<double>*, int, CandidatePairs&,
                                       const std::function<void(std::uint64_t, bool)>*,
                                       const EntryBodies<float>*);
template std::uint64_t find_candidates(const Entries<std::uint64_t>&, const PackedBodies<float>&,
                                       std::span<const std::uint8_t>, int, CandidateFilter,
                                       const NarrowBodies<double>*, int, CandidatePairs&,
                                       const std::function<void(std::uint64_t, bool)>*,
                                       const EntryBodies<float>*);
template std::uint64_t find_candidates(const Entries<std::uint32_t>&, const PackedBodies<double>&,
                                       std::span<const std::uint8_t>, int, CandidateFilter,
                                       const NarrowBodies<double>*, int, CandidatePairs&,
                                       const std::function<void(std::uint64_t, bool)>*,
                                       const EntryBodies<double>*);
template std::uint64_t find_candidates(const Entries<std::uint64_t>&, const PackedBodies<double>&,
                                       std::span<const std::uint8_t>, int, CandidateFilter,
                                       const NarrowBodies<double>*, int, CandidatePairs&,
                                       const std::function<void(std::uint64_t, bool)>*,
                                       const EntryBodies<double>*);

}  // namespace cg::detail::host
