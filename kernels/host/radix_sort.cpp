// Stable radix sort of the CPU backend (see radix_sort.hpp). Kept out of the header so that every
// caller uses this one OpenMP-compiled definition (a template instantiated in a TU built without
// OpenMP would silently sort only the first thread's chunk).
#include "host/radix_sort.hpp"

#include <omp.h>

#include <algorithm>
#include <cstdlib>
#include <string_view>
#include <type_traits>

namespace cg::detail {

namespace {

// Below this many elements the LSD passes alone (the top digit's buckets would be too few).
constexpr std::size_t k_top_digit_min = std::size_t(1) << 17;

// Stable counting sort of [0, n) by the digit (key >> shift) & mask, src → dst, on the calling thread
// (a bucket of the top-digit-first sort: small enough for the cache). `count`: 2^width scratch.
template <class Key, class Value>
void local_pass(const Key* ksrc, const Value* vsrc, Key* kdst, Value* vdst, std::size_t n, int shift,
                Key mask, std::size_t* count) {
  constexpr bool with_values = !std::is_same_v<Value, NoValues>;
  std::fill(count, count + std::size_t(mask) + 1, std::size_t(0));
  for (std::size_t i = 0; i < n; ++i) ++count[(ksrc[i] >> shift) & mask];
  std::size_t sum = 0;
  for (std::size_t d = 0; d <= std::size_t(mask); ++d) {
    const std::size_t c = count[d];
    count[d] = sum;
    sum += c;
  }
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t pos = count[(ksrc[i] >> shift) & mask]++;
    kdst[pos] = ksrc[i];
    if constexpr (with_values) vdst[pos] = vsrc[i];
  }
}

// Within a parallel region of `team` threads (an orphaned barrier and single bind to it): thread t
// counts the digits (key >> shift) & mask of its chunk [lo, hi) of `keys`, and then every thread's
// first place for each digit, digit by digit and thread by thread within a digit (what makes the
// scatter stable), replaces the counts in hist (team × buckets). on_digit(d, first) sees where each
// digit's run starts, and (buckets, n) last. Returns thread t's row of places, which its scatter
// advances.
template <class Key, class OnDigit>
std::size_t* digit_offsets(const Key* keys, std::size_t lo, std::size_t hi, int shift, Key mask,
                           std::size_t* hist, std::size_t buckets, int t, int team, OnDigit&& on_digit) {
  std::size_t* h = hist + std::size_t(t) * buckets;
  std::fill(h, h + buckets, 0);
  for (std::size_t i = lo; i < hi; ++i) ++h[(keys[i] >> shift) & mask];
#pragma omp barrier
#pragma omp single
  {
    std::size_t sum = 0;
    for (std::size_t d = 0; d < buckets; ++d) {
      on_digit(d, sum);
      for (int u = 0; u < team; ++u) {
        const std::size_t c = hist[std::size_t(u) * buckets + d];
        hist[std::size_t(u) * buckets + d] = sum;
        sum += c;
      }
    }
    on_digit(buckets, sum);
  }
  return h;
}

// The LSD passes that sort a bucket by its low `shift` bits: of up to 11 bits each.
int bucket_passes(int shift) { return (shift + 10) / 11; }

// Within a parallel region (an orphaned `omp for` over the buckets): bucket d = [start[d], start[d + 1])
// of (ks, vs), in stable order by the bits above `shift`, sorted by its low `shift` bits with LSD passes
// on one thread (in the cache), between (ks, vs) and (kd, vd). The buckets end in kd where the passes
// are odd in number, else in ks (a lone element copied there too).
template <class Key, class Value>
void sort_buckets(Key* ks0, Value* vs0, Key* kd0, Value* vd0, const std::size_t* start, std::size_t buckets,
                  int shift) {
  constexpr bool with_values = !std::is_same_v<Value, NoValues>;
  const int passes = bucket_passes(shift);
  const int width = passes > 0 ? (shift + passes - 1) / passes : 0;
  std::vector<std::size_t> count(std::size_t(1) << width);
#pragma omp for schedule(dynamic, 4)
  for (std::size_t d = 0; d < buckets; ++d) {
    const std::size_t b0 = start[d], m = start[d + 1] - b0;
    Key *ks = ks0 + b0, *kd = kd0 + b0;
    Value *vs = with_values ? vs0 + b0 : nullptr, *vd = with_values ? vd0 + b0 : nullptr;
    for (int pass = 0; pass < passes && m > 1; ++pass) {
      local_pass(ks, vs, kd, vd, m, pass * width, Key((Key(1) << width) - 1), count.data());
      std::swap(ks, kd);
      std::swap(vs, vd);
    }
    if (m == 1 && passes % 2 == 1) {  // a lone element still ends where the others do
      kd0[b0] = ks0[b0];
      if constexpr (with_values) vd0[b0] = vs0[b0];
    }
  }
}

// The top digit first: one parallel stable scatter of keys (and values) into key_tmp by the top
// `top` bits of the `bits`, then each bucket (on average a few thousand elements: in the cache)
// sorted by the remaining low bits with LSD passes on one thread, buckets shared among the threads.
// A stable sort's result is unique, so this gives the LSD sort's bytes with one pass over memory in
// place of two or more (each LSD pass scatters the whole array to every bucket at random). Returns
// false, sorting nothing, where the top digit splits the keys badly (a bucket above n / 16: keys
// that use fewer bits than `bits`, or clustered ones); else whether the result ends in the scratch.
template <class Key, class Value>
bool top_digit_first(Key* keys, Value* values, Key* key_tmp, Value* value_tmp, std::size_t n, int bits,
                     int nt, bool& in_tmp) {
  constexpr bool with_values = !std::is_same_v<Value, NoValues>;
  int top = 1;  // buckets of about 2048 elements or more, at most 256 of them
  while (top < 8 && top < bits && (n >> (top + 1)) >= 2048) ++top;
  const int shift = bits - top;
  const std::size_t buckets = std::size_t(1) << top;
  const Key mask = Key(buckets - 1);
  std::vector<std::size_t> hist(std::size_t(nt) * buckets);
  std::vector<std::size_t> start(buckets + 1);
  bool skewed = false;
  int team = 1;
#pragma omp parallel num_threads(nt)
  {
#pragma omp single
    team = omp_get_num_threads();
    const int t = omp_get_thread_num();
    const std::size_t lo = n * t / team, hi = n * (t + 1) / team;
    std::size_t* h = digit_offsets(keys, lo, hi, shift, mask, hist.data(), buckets, t, team,
                                   [&](std::size_t d, std::size_t first) {
                                     start[d] = first;
                                     skewed = skewed || (d > 0 && (first - start[d - 1]) * 16 > n);
                                   });
    if (!skewed) {
      for (std::size_t i = lo; i < hi; ++i) {
        const std::size_t pos = h[(keys[i] >> shift) & mask]++;
        key_tmp[pos] = keys[i];
        if constexpr (with_values) value_tmp[pos] = values[i];
      }
#pragma omp barrier
      sort_buckets(key_tmp, value_tmp, keys, values, start.data(), buckets, shift);
    }
  }
  in_tmp = bucket_passes(shift) % 2 == 0;
  return !skewed;
}

}  // namespace

template <class Key, class Value>
bool radix_sort_buckets(Key* keys, Value* values, Key* key_tmp, Value* value_tmp, const std::size_t* start,
                        std::size_t buckets, int shift, int threads) {
  int nt = threads > 0 ? threads : omp_get_max_threads();
  nt = int(std::max<std::size_t>(1, std::min<std::size_t>(nt, buckets)));
#pragma omp parallel num_threads(nt)
  sort_buckets(keys, values, key_tmp, value_tmp, start, buckets, shift);
  return bucket_passes(shift) % 2 == 1;
}

template <class Key, class Value>
bool radix_sort_arrays(Key* keys, Value* values, Key* key_tmp, Value* value_tmp, std::size_t n, int bits,
                       int threads) {
  constexpr bool with_values = !std::is_same_v<Value, NoValues>;
  if (n < 2 || bits <= 0) return false;
  const char* knob = std::getenv("CONTACTGRID_HOST_SORT");
  if (bits > 11 && n >= k_top_digit_min && !(knob != nullptr && std::string_view(knob) == "lsd")) {
    int nt = threads > 0 ? threads : omp_get_max_threads();
    nt = int(std::max<std::size_t>(1, std::min<std::size_t>(nt, n / 65536 + 1)));
    bool in_tmp = false;
    if (top_digit_first(keys, values, key_tmp, value_tmp, n, bits, nt, in_tmp)) return in_tmp;
  }
  const int passes = (bits + 10) / 11;
  const int width = (bits + passes - 1) / passes;
  const std::size_t buckets = std::size_t(1) << width;
  const Key mask = Key(buckets - 1);
  int nt = threads > 0 ? threads : omp_get_max_threads();
  nt = int(std::max<std::size_t>(1, std::min<std::size_t>(nt, n / 262144 + 1)));

  std::vector<std::size_t> hist(std::size_t(nt) * buckets);
  Key* ksrc = keys;
  Key* kdst = key_tmp;
  Value* vsrc = values;
  Value* vdst = value_tmp;
  for (int pass = 0; pass < passes; ++pass) {
    const int shift = pass * width;
    int team = 1;
#pragma omp parallel num_threads(nt)
    {
      // The runtime may give fewer threads than asked: chunks follow the actual team size.
#pragma omp single
      team = omp_get_num_threads();
      const int t = omp_get_thread_num();
      const std::size_t lo = n * t / team, hi = n * (t + 1) / team;
      std::size_t* h = digit_offsets(ksrc, lo, hi, shift, mask, hist.data(), buckets, t, team,
                                     [](std::size_t, std::size_t) {});
      for (std::size_t i = lo; i < hi; ++i) {
        const std::size_t pos = h[(ksrc[i] >> shift) & mask]++;
        kdst[pos] = ksrc[i];
        if constexpr (with_values) vdst[pos] = vsrc[i];
      }
    }
    std::swap(ksrc, kdst);
    if constexpr (with_values) std::swap(vsrc, vdst);
  }
  return ksrc != keys;
}

template bool radix_sort_arrays(std::uint32_t*, std::uint32_t*, std::uint32_t*, std::uint32_t*, std::size_t,
                                int, int);
template bool radix_sort_arrays(std::uint64_t*, std::uint32_t*, std::uint64_t*, std::uint32_t*, std::size_t,
                                int, int);
template bool radix_sort_arrays(std::uint32_t*, NoValues*, std::uint32_t*, NoValues*, std::size_t, int, int);
template bool radix_sort_arrays(std::uint64_t*, NoValues*, std::uint64_t*, NoValues*, std::size_t, int, int);
template bool radix_sort_buckets(std::uint32_t*, std::uint32_t*, std::uint32_t*, std::uint32_t*,
                                 const std::size_t*, std::size_t, int, int);
template bool radix_sort_buckets(std::uint64_t*, std::uint32_t*, std::uint64_t*, std::uint32_t*,
                                 const std::size_t*, std::size_t, int, int);

}  // namespace cg::detail
