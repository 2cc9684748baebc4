// The one-rank order's sums from each rank's own items (src/simulate/rank_records.hpp): whatever the
// ranks hold, the records they send give the tree sum of core/dem_sum.hpp over every item in order,
// bit for bit, and the runs of ids place each rank's items (a body's contacts) where the one-rank
// order has them. The ranks are simulated here (their records concatenated); the CLI's MPI runs
// (tests/cli/mpi_simulate.sh) check the same through mpirun.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "core/dem_sum.hpp"
#include "simulate/rank_records.hpp"

namespace cg::test {
namespace {

using sim::SumRecord;

// Values whose sum depends on its order: mixed signs and magnitudes, a few −0.
std::vector<std::array<double, 2>> order_sensitive_values(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  std::uniform_int_distribution<int> e(-30, 30);
  std::vector<std::array<double, 2>> v(n);
  for (std::size_t i = 0; i < n; ++i) {
    v[i] = {std::ldexp(u(rng), e(rng)), u(rng)};
    if (i % 97 == 5) v[i][0] = -0.0;
  }
  return v;
}

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// The owners of `n` items among `p` ranks: slabs of consecutive items, at random, or round robin.
std::vector<int> owners(std::size_t n, int p, int how, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<int> o(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (how == 0)
      o[i] = static_cast<int>(i * std::size_t(p) / std::max<std::size_t>(n, 1));
    else if (how == 1)
      o[i] = static_cast<int>(rng() % std::uint64_t(p));
    else
      o[i] = static_cast<int>(i % std::size_t(p));
  }
  return o;
}

// Every simulated rank's records, concatenated in rank order (as gather_records gives them).
template <int S>
std::vector<SumRecord<S>> all_records(std::size_t n, int p, const std::vector<int>& owner,
                                      const std::vector<std::array<double, S>>& v) {
  std::vector<SumRecord<S>> all;
  for (int r = 0; r < p; ++r) {
    std::vector<std::uint64_t> at;
    std::vector<std::array<double, S>> mine;
    for (std::size_t i = 0; i < n; ++i)
      if (owner[i] == r) {
        at.push_back(i);
        mine.push_back(v[i]);
      }
    const std::vector<SumRecord<S>> rec = sim::sum_records<S>(n, at, mine);
    all.insert(all.end(), rec.begin(), rec.end());
  }
  return all;
}

TEST(RankSums, ChunkRecordsGiveTheOneRankTreeSum) {
  for (const std::size_t n : {0, 1, 31, 32, 33, 1000, 1024, 1025, 40000}) {
    const std::vector<std::array<double, 2>> v = order_sensitive_values(n, n + 3);
    const double want0 = dem::tree_sum(n, [&](std::size_t i) { return v[i][0]; });
    const double want1 = dem::tree_sum(n, [&](std::size_t i) { return v[i][1]; });
    for (const int p : {1, 2, 3, 5}) {
      for (int how = 0; how < 3; ++how) {
        const std::string at =
            "n " + std::to_string(n) + ", " + std::to_string(p) + " ranks, owners " + std::to_string(how);
        const std::vector<int> owner = owners(n, p, how, n * 7 + std::uint64_t(p));
        std::vector<SumRecord<2>> records = all_records<2>(n, p, owner, v);
        const std::array<double, 2> got = sim::sums_from_records<2>(n, records);
        EXPECT_TRUE(same_bits(got[0], want0)) << at << ": " << got[0] << " vs " << want0;
        EXPECT_TRUE(same_bits(got[1], want1)) << at << ": " << got[1] << " vs " << want1;
        if (how == 0) {  // slabs: about one record per chunk, the items of the chunks at the cuts
          EXPECT_LE(records.size(), dem::energy_chunks(n) + std::size_t(p) * dem::kEnergyChunk) << at;
        }
        // the records in any order give the same
        std::reverse(records.begin(), records.end());
        const std::array<double, 2> again = sim::sums_from_records<2>(n, records);
        EXPECT_TRUE(same_bits(again[0], want0)) << at << " (records reversed)";
      }
    }
  }
  // the order matters for these values: a plain sum differs from the tree's
  const std::vector<std::array<double, 2>> v = order_sensitive_values(40000, 40003);
  double plain = 0;
  for (const auto& x : v) plain += x[0];
  EXPECT_FALSE(same_bits(plain, dem::tree_sum(v.size(), [&](std::size_t i) { return v[i][0]; })));
}

TEST(RankSums, RecordsMissingOrTwiceAreAnInternalError) {
  const std::size_t n = 200;
  const std::vector<std::array<double, 2>> v = order_sensitive_values(n, 9);
  const std::vector<int> owner = owners(n, 3, 1, 4);
  const std::vector<SumRecord<2>> records = all_records<2>(n, 3, owner, v);
  ASSERT_GT(records.size(), 1u);
  for (std::size_t drop : {std::size_t(0), records.size() / 2, records.size() - 1}) {
    std::vector<SumRecord<2>> fewer = records;
    fewer.erase(fewer.begin() + std::ptrdiff_t(drop));
    EXPECT_THROW(sim::sums_from_records<2>(n, fewer), Error) << "record " << drop << " dropped";
    std::vector<SumRecord<2>> twice = records;
    twice.push_back(records[drop]);
    EXPECT_THROW(sim::sums_from_records<2>(n, twice), Error) << "record " << drop << " twice";
  }
  // a whole chunk and its items both
  std::vector<std::uint64_t> at(32);
  std::iota(at.begin(), at.end(), 0);
  std::vector<SumRecord<2>> both =
      sim::sum_records<2>(n, at, std::vector<std::array<double, 2>>(v.begin(), v.begin() + 32));
  ASSERT_EQ(both.size(), 1u);
  both.insert(both.end(), records.begin(), records.end());
  EXPECT_THROW(sim::sums_from_records<2>(n, both), Error);
  // positions not ascending, or past the total
  EXPECT_THROW(sim::sum_records<2>(n, {3, 2}, {v[0], v[1]}), Error);
  EXPECT_THROW(sim::sum_records<2>(n, {5, n}, {v[0], v[1]}), Error);
  EXPECT_THROW(sim::sums_from_records<2>(0, records), Error);
}

TEST(RankSums, RunsPlaceEachRanksItemsInTheOneRankOrder) {
  for (const int p : {1, 2, 4}) {
    for (int how = 0; how < 3; ++how) {
      const std::size_t n = 3000;
      std::mt19937_64 rng(std::uint64_t(p) * 11 + std::uint64_t(how));
      std::vector<std::uint64_t> count(n);
      for (auto& c : count) c = rng() % 8;         // some ids without items
      std::vector<std::uint64_t> first(n + 1, 0);  // the one-rank order: by id
      for (std::size_t i = 0; i < n; ++i) first[i + 1] = first[i] + count[i];
      const std::vector<int> owner = owners(n, p, how, 17);
      const std::size_t np = static_cast<std::size_t>(p);
      std::vector<std::vector<std::int64_t>> ids(np);
      std::vector<std::vector<std::uint64_t>> items(np);
      std::vector<sim::IdRun> all;
      for (std::size_t i = 0; i < n; ++i) {
        ids[std::size_t(owner[i])].push_back(std::int64_t(i));
        items[std::size_t(owner[i])].push_back(count[i]);
      }
      std::vector<std::vector<sim::IdRun>> runs(np);
      for (std::size_t r = 0; r < std::size_t(p); ++r) {
        runs[r] = sim::id_runs(ids[r], items[r]);
        all.insert(all.end(), runs[r].begin(), runs[r].end());
      }
      if (how == 0) {
        EXPECT_EQ(all.size(), std::size_t(p)) << "slabs: one run a rank";
      }
      for (std::size_t r = 0; r < std::size_t(p); ++r) {
        std::uint64_t total = 0;
        const std::vector<std::uint64_t> off = sim::run_offsets(all, runs[r], n, total);
        EXPECT_EQ(total, first[n]);
        // each id's items from its run's first position on, as ResidentDem::log_sums places them
        std::size_t j = 0;
        for (std::size_t k = 0; k < runs[r].size(); ++k) {
          std::uint64_t at = off[k];
          for (; j < ids[r].size() && ids[r][j] < runs[r][k].end; ++j) {
            ASSERT_EQ(at, first[std::size_t(ids[r][j])]) << p << " ranks, id " << ids[r][j];
            at += items[r][j];
          }
        }
        EXPECT_EQ(j, ids[r].size());
      }
      // runs that leave an id out, or hold one twice
      if (all.size() > 1) {
        std::vector<sim::IdRun> gap(all.begin() + 1, all.end());
        std::uint64_t total = 0;
        EXPECT_THROW(sim::run_offsets(gap, {}, n, total), Error);
        std::vector<sim::IdRun> twice = all;
        twice.push_back(all[0]);
        EXPECT_THROW(sim::run_offsets(twice, {}, n, total), Error);
      }
      std::uint64_t total = 0;
      EXPECT_THROW(sim::run_offsets(all, {}, n + 1, total), Error);
    }
  }
}

}  // namespace
}  // namespace cg::test
