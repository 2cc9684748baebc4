// The CPU backend's radix sort: stable, sorts only the requested low bits, any thread count.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "host/radix_sort.hpp"

namespace cg::detail {
namespace {

template <class Key>
void check(std::size_t n, int bits, int threads, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Key> keys(n);
  std::vector<std::uint32_t> values(n);
  const Key mask = bits >= int(8 * sizeof(Key)) ? Key(~Key(0)) : Key((Key(1) << bits) - 1);
  for (std::size_t i = 0; i < n; ++i) {
    keys[i] = Key(rng()) & mask;
    if (i % 7 == 0 && i) keys[i] = keys[i - 1];  // many equal keys: stability matters
    values[i] = std::uint32_t(i);
  }
  std::vector<std::pair<Key, std::uint32_t>> want(n);
  for (std::size_t i = 0; i < n; ++i) want[i] = {keys[i], values[i]};
  std::stable_sort(want.begin(), want.end(), [](auto& a, auto& b) { return a.first < b.first; });
  radix_sort(keys, values, bits, threads);
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_EQ(keys[i], want[i].first) << "n=" << n << " bits=" << bits << " at " << i;
    ASSERT_EQ(values[i], want[i].second) << "not stable at " << i;
  }
}

TEST(RadixSort, StableOverTheRequestedBits) {
  for (int threads : {1, 2, 3})
    for (std::size_t n : {0u, 1u, 2u, 1000u, 300000u}) {
      check<std::uint32_t>(n, 22, threads, n + 1);
      check<std::uint32_t>(n, 32, threads, n + 2);
      check<std::uint64_t>(n, 41, threads, n + 3);
      check<std::uint64_t>(n, 7, threads, n + 4);
    }
}

// Sizes where the top digit goes first (host/radix_sort.cpp: its buckets sorted on one thread each),
// and keys clustered under a few top digits (the LSD passes instead) or using fewer bits than asked.
TEST(RadixSort, TopDigitFirstAndItsFallback) {
  for (int threads : {1, 2, 3}) {
    check<std::uint32_t>(600000, 18, threads, 11);
    check<std::uint32_t>(600000, 12, threads, 12);
    check<std::uint64_t>(420000, 40, threads, 13);
    check<std::uint32_t>(300001, 31, threads, 14);
  }
  for (int threads : {1, 2}) {
    std::mt19937 rng(15);
    std::vector<std::uint32_t> keys(400000), values(400000);
    for (std::size_t i = 0; i < keys.size(); ++i) {
      keys[i] = (i % 3 == 0 ? 0u : (1u << 19) | (rng() & 0xffffu)) | (rng() & 0x3fu) << 24;  // above 20 bits
      values[i] = std::uint32_t(i);
    }
    std::vector<std::pair<std::uint32_t, std::uint32_t>> want(keys.size());
    for (std::size_t i = 0; i < keys.size(); ++i) want[i] = {keys[i], values[i]};
    const auto low = [](std::uint32_t k) { return k & ((1u << 20) - 1); };
    std::stable_sort(want.begin(), want.end(), [&](auto& a, auto& b) { return low(a.first) < low(b.first); });
    radix_sort(keys, values, 20, threads);
    for (std::size_t i = 0; i < keys.size(); ++i) {
      ASSERT_EQ(keys[i], want[i].first) << i;
      ASSERT_EQ(values[i], want[i].second) << i;
    }
  }
}

TEST(RadixSort, KeysOnly) {
  std::vector<std::uint64_t> k{5, 3, 9, 3, 0, 1ull << 40};
  radix_sort_keys(k, 41, 2);
  EXPECT_TRUE(std::is_sorted(k.begin(), k.end()));
}

}  // namespace
}  // namespace cg::detail
