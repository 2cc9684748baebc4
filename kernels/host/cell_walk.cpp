// Host stage pairs of the cell list: each body against the later bodies of its cell and those of the
// 13 cells of a half stencil, over the bodies gathered in cell order (see stages.hpp).
#include <algorithm>
#include <cstring>
#include <functional>

#include "backend.hpp"
#include "host/pair_walk.hpp"
#include "host/stages.hpp"

namespace cg::detail::host {
namespace {

// The half stencil beside a body's own row of cells (own cell and the next along x): the rows
// (dy, dz) = (1, 0), (−1, 1), (0, 1), (1, 1), each three cells x − 1 … x + 1 long; as key offsets of
// their middle cells.
constexpr int k_rows = 4;
constexpr std::uint32_t k_lanes = 4;  // places a block of the walk's inner loop tests at once
struct RowOffsets {
  std::uint32_t off[k_rows];
  explicit RowOffsets(const std::uint32_t* dims) {
    const std::uint32_t dx = dims[0], dxy = dims[0] * dims[1];
    off[0] = dx;
    off[1] = dxy - dx;
    off[2] = dxy;
    off[3] = dxy + dx;
  }
};

// NearBound's test of places j0 … j0 + k_lanes − 1 against sphere a: bit l set where d² <= s², s =
// (ra + rb) + margin2, on vectors of k_lanes (the same roundings lane by lane as the scalar test).
template <class Real>
struct LaneVector;
template <>
struct LaneVector<float> {
  using type = float __attribute__((vector_size(k_lanes * sizeof(float))));
};
template <>
struct LaneVector<double> {
  using type = double __attribute__((vector_size(k_lanes * sizeof(double))));
};

template <class Real>
unsigned near_lanes(Real ax, Real ay, Real az, Real ar, Real margin2, const Real* x, const Real* y,
                    const Real* z, const Real* r, std::uint32_t j0) {
  using V = typename LaneVector<Real>::type;
  V bx, by, bz, br;
  std::memcpy(&bx, x + j0, sizeof(V));
  std::memcpy(&by, y + j0, sizeof(V));
  std::memcpy(&bz, z + j0, sizeof(V));
  std::memcpy(&br, r + j0, sizeof(V));
  const V dx = ax - bx, dy = ay - by, dz = az - bz;
  const V d2 = dx * dx + dy * dy + dz * dz;
  const V sum = (ar + br) + margin2;
  const auto near = d2 <= sum * sum;
  unsigned bits = 0;
  for (std::uint32_t l = 0; l < k_lanes; ++l) bits |= unsigned(near[l] & 1) << l;
  return bits;
}

// The bodies in cell order, structure of arrays: packed sphere (radius plus the inflation) and input
// index, gathered once so that the walk reads memory in sequence.
template <class Real>
struct ListBodies {
  Array<Real> x, y, z, r;
  Array<std::uint32_t> id;
};

template <class Real>
void gather(const CellList<Real>& cl, const PackedBodies<Real>& p, int nt, ListBodies<Real>& lb) {
  const std::size_t n = cl.key.size();
  // k_lanes places more, never a pair: the walk's last block reads past the last place
  for (auto* a : {&lb.x, &lb.y, &lb.z, &lb.r}) {
    a->resize(n + k_lanes);
    std::fill(a->begin() + std::ptrdiff_t(n), a->end(), Real(0));
  }
  lb.id.resize(n + k_lanes);
  constexpr std::size_t ahead = 16;  // the bodies of a cell are random places in input order
#pragma omp parallel for num_threads(nt) schedule(static) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    if (i + ahead < n) __builtin_prefetch(p.spheres.data() + cl.body[i + ahead]);
    const std::uint32_t b = cl.body[i];
    const Sphere<Real> s = p.spheres[b];
    lb.x[i] = s.x;
    lb.y[i] = s.y;
    lb.z[i] = s.z;
    lb.r[i] = s.r + p.inflation;
    lb.id[i] = b;
  }
}

// Sorted places [lo, hi): each against the later places of its cell and the next, and the three
// cells of each row of the half stencil; `test` decides the pairs NearBound leaves (on input indices,
// the smaller first, as every pair stage calls it). Returns the pairs tested.
template <class Test, class Real, class Emit>
std::uint64_t walk(std::size_t lo, std::size_t hi, const CellList<Real>& cl, const ListBodies<Real>& lb,
                   const Test& test, Emit&& emit) {
  const Real *x = lb.x.data(), *y = lb.y.data(), *z = lb.z.data(), *r = lb.r.data();
  const std::uint32_t* id = lb.id.data();
  const std::uint32_t *key = cl.key.data(), *start = cl.start.data();
  const RowOffsets rows(cl.dims);
  const NearBound<Test, Real> near_bound(test);
  const bool all = near_bound.all;
  const Real margin2 = near_bound.margin2;
  std::uint64_t tests = 0;
  for (std::size_t i = lo; i < hi; ++i) {
    const Real ax = x[i], ay = y[i], az = z[i], ar = r[i];
    const std::uint32_t a = id[i], k = key[i];
    // the ranges of places: the rest of the own cell and the next, then the rows
    std::uint32_t from[k_rows + 1], to[k_rows + 1];
    from[0] = static_cast<std::uint32_t>(i + 1);
    to[0] = start[k + 2];
    for (int q = 0; q < k_rows; ++q) {
      from[q + 1] = start[k + rows.off[q] - 1];
      to[q + 1] = start[k + rows.off[q] + 2];
    }
    for (int q = 0; q <= k_rows; ++q) {
      tests += to[q] - from[q];
      // blocks of k_lanes places, the first one whether the range is empty or not (the arrays hold
      // k_lanes places more): a fixed loop without a branch a place, the places past the range masked
      std::uint32_t j0 = from[q];
      do {
        const std::uint32_t left = to[q] > j0 ? to[q] - j0 : 0;
        const unsigned in_range = left >= k_lanes ? (1u << k_lanes) - 1 : (1u << left) - 1;
        const unsigned hits = all ? in_range : in_range & near_lanes(ax, ay, az, ar, margin2, x, y, z, r, j0);
        for (unsigned h = hits; h != 0; h &= h - 1) {
          const std::uint32_t j = j0 + std::uint32_t(__builtin_ctz(h));
          const std::uint32_t b = id[j];
          const Sphere<Real> sa{ax, ay, az, ar}, sb{x[j], y[j], z[j], r[j]};
          if (a < b ? test(sa, sb, a, b) : test(sb, sa, b, a)) a < b ? emit(a, b) : emit(b, a);
        }
        j0 += k_lanes;
      } while (j0 < to[q]);
    }
  }
  return tests;
}

template <class Test, class Real>
std::uint64_t collect(const CellList<Real>& cl, const PackedBodies<Real>& p, int nt, const Test& test,
                      CandidatePairs& out, ProgressShare& progress) {
  const std::size_t n = cl.key.size();
  ListBodies<Real> lb;
  gather(cl, p, nt, lb);
  // chunks of listed bodies, each appending its pairs to its thread's buffer (collect_in_chunks)
  return collect_in_chunks(n, nt, out, progress, [&](std::size_t begin, std::size_t end, auto& emit) {
    return walk(begin, end, cl, lb, test, emit);
  });
}

}  // namespace

template <class Real>
PairEstimate cell_list_estimate(const CellList<Real>& cl, int threads) {
  const std::size_t n = cl.key.size();
  const std::uint32_t *key = cl.key.data(), *start = cl.start.data();
  const RowOffsets rows(cl.dims);
  std::uint64_t tests = 0, largest = 0;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(+ : tests) reduction(max : largest) \
    if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t k = key[i];
    largest = std::max<std::uint64_t>(largest, start[k + 1] - start[k]);
    tests += start[k + 2] - (i + 1);
    for (int q = 0; q < k_rows; ++q) tests += start[k + rows.off[q] + 2] - start[k + rows.off[q] - 1];
  }
  return {tests, n, n, largest};
}

template <class Real>
std::uint64_t cell_list_candidates(const CellList<Real>& cl, const PackedBodies<Real>& p,
                                   CandidateFilter filter, const NarrowBodies<double>* fp64, int threads,
                                   CandidatePairs& out,
                                   const std::function<void(std::uint64_t, bool)>* on_progress) {
  ProgressShare progress(on_progress);
  out.id_bits = std::max(1, bits_for(p.spheres.size()));
  out.filter = filter;
  if (cl.key.empty()) {
    out.ab.clear();
    progress.finish();
    return 0;
  }
  return with_pair_test(filter, p, fp64,
                        [&](const auto& test) { return collect(cl, p, threads, test, out, progress); });
}

template PairEstimate cell_list_estimate(const CellList<float>&, int);
template PairEstimate cell_list_estimate(const CellList<double>&, int);
template std::uint64_t cell_list_candidates(const CellList<float>&, const PackedBodies<float>&,
                                            CandidateFilter, const NarrowBodies<double>*, int,
                                            CandidatePairs&, const std::function<void(std::uint64_t, bool)>*);
template std::uint64_t cell_list_candidates(const CellList<double>&, const PackedBodies<double>&,
                                            CandidateFilter, const NarrowBodies<double>*, int,
                                            CandidatePairs&, const std::function<void(std::uint64_t, bool)>*);

}  // namespace cg::detail::host
