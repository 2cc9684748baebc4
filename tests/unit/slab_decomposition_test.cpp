// Unit tests of decomposition/: slab cuts, ownership, halo plan. Pure geometry, no MPI.
// Pictures: slabs along the slab axis, "|" an interior cut, "[" a closed end, "(" an open one.
#include "slab_decomposition.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "routing.hpp"

namespace cg {
namespace {

std::vector<int> ghost_ranks(const SlabDecomposition& s, double x, double w) {
  std::vector<int> out;
  s.for_each_ghost_rank(x, w, [&](int r) { out.push_back(r); });
  return out;
}

// Bodies exactly on a cut belong to the upper slab.
//
//      rank 0       rank 1        rank 2        rank 3
//   (-inf ...... 0)[0 ...... 10)[10 ...... 20)[20 ...... +inf)
TEST(SlabDecomposition, OwnershipIsHalfOpenUpperSlabTakesTheCut) {
  SlabDecomposition s(0, {0.0, 10.0, 20.0});
  EXPECT_EQ(s.ranks(), 4);
  EXPECT_EQ(s.owner(-1e300), 0);
  EXPECT_EQ(s.owner(std::nextafter(0.0, -1.0)), 0);
  EXPECT_EQ(s.owner(0.0), 1);
  EXPECT_EQ(s.owner(-0.0), 1);  // -0 == 0: on the cut
  EXPECT_EQ(s.owner(std::nextafter(10.0, 0.0)), 1);
  EXPECT_EQ(s.owner(10.0), 2);
  EXPECT_EQ(s.owner(20.0), 3);
  EXPECT_EQ(s.owner(1e300), 3);
  EXPECT_EQ(s.lower(0), -std::numeric_limits<double>::infinity());
  EXPECT_EQ(s.upper(3), std::numeric_limits<double>::infinity());
  EXPECT_EQ(s.lower(2), 10.0);
  EXPECT_EQ(s.upper(2), 20.0);
  for (int r = 0; r < 4; ++r) EXPECT_FALSE(s.empty(r));
}

// Equal cuts make empty slabs, which own nothing and never receive ghosts.
//
//      rank 0      rank 1 = [5,5)   rank 2 = [5,5)    rank 3
//   (-inf ..... 5)|               |               [5 ...... +inf)
TEST(SlabDecomposition, EqualCutsGiveEmptySlabs) {
  SlabDecomposition s(1, {5.0, 5.0, 5.0});
  EXPECT_FALSE(s.empty(0));
  EXPECT_TRUE(s.empty(1));
  EXPECT_TRUE(s.empty(2));
  EXPECT_FALSE(s.empty(3));
  EXPECT_EQ(s.owner(5.0), 3);
  EXPECT_EQ(s.owner(4.999), 0);
  EXPECT_EQ(ghost_ranks(s, 4.5, 1.0), (std::vector<int>{3}));
  EXPECT_EQ(ghost_ranks(s, 5.5, 1.0), (std::vector<int>{0}));
}

TEST(SlabDecomposition, RejectsBadCuts) {
  EXPECT_THROW(SlabDecomposition(0, {1.0, 0.0}), InputError);
  EXPECT_THROW(SlabDecomposition(0, {std::nan("")}), InputError);
  EXPECT_THROW(SlabDecomposition(0, {std::numeric_limits<double>::infinity()}), InputError);
  EXPECT_THROW(SlabDecomposition(3, {}), UsageError);
}

// One rank: one slab (-inf, +inf), owns everything, no ghosts anywhere.
TEST(SlabDecomposition, OneRankOwnsEverythingAndHasNoHalo) {
  const std::vector<double> sample = {3, 1, 2};
  SlabDecomposition s = SlabDecomposition::from_sorted_sample(2, sample, 1);
  EXPECT_EQ(s.ranks(), 1);
  EXPECT_TRUE(s.cuts().empty());
  EXPECT_EQ(s.owner(-1e300), 0);
  EXPECT_EQ(s.owner(1e300), 0);
  const std::vector<double> x = {-5, 0, 1e6};
  ExportPlan halo = make_halo_plan(s, 0, x, 1e9);
  EXPECT_EQ(halo.total(), 0u);
  ExportPlan owners = make_owner_plan(s, x);
  EXPECT_EQ(owners.count(0), 3u);
}

// Quantile cuts: cut r = sample[floor(r·S/P)]. Ten bodies, three ranks:
//
//   x:     0 1 2 | 3 4 5 | 6 7 8 9
//        rank 0   rank 1   rank 2       (3, 3, 4 bodies)
TEST(SlabDecomposition, QuantileCutsBalanceCounts) {
  std::vector<double> x = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9};
  SlabDecomposition s = SlabDecomposition::from_sorted_sample(0, x, 3);
  EXPECT_EQ(s.cuts(), (std::vector<double>{3, 6}));
  ExportPlan plan = make_owner_plan(s, x);
  EXPECT_EQ(plan.count(0), 3u);
  EXPECT_EQ(plan.count(1), 3u);
  EXPECT_EQ(plan.count(2), 4u);
}

TEST(SlabDecomposition, QuantileCutsOfDistinctValuesGiveFloorOrCeilPerRank) {
  std::mt19937_64 rng(12345);
  std::uniform_real_distribution<double> u(-50, 50);
  for (int ranks : {1, 2, 3, 4, 7, 16}) {
    std::vector<double> x(1001);
    for (double& v : x) v = u(rng);
    std::vector<double> sorted = x;
    std::sort(sorted.begin(), sorted.end());
    SlabDecomposition s = SlabDecomposition::from_sorted_sample(0, sorted, ranks);
    ExportPlan plan = make_owner_plan(s, x);
    const std::size_t lo = x.size() / ranks, hi = (x.size() + ranks - 1) / ranks;
    for (int r = 0; r < ranks; ++r) {
      EXPECT_GE(plan.count(r), lo) << "ranks " << ranks << " rank " << r;
      EXPECT_LE(plan.count(r), hi) << "ranks " << ranks << " rank " << r;
    }
  }
}

// More ranks than bodies: two bodies at 1 and 2, four ranks. Cuts {1, 2, 2}:
//
//      rank 0       rank 1     rank 2 = [2,2)    rank 3
//   (-inf .... 1)[1 ....... 2)|              [2 ...... +inf)
//                 body 0                        body 1
TEST(SlabDecomposition, MoreRanksThanBodies) {
  const std::vector<double> x = {1.0, 2.0};
  SlabDecomposition s = SlabDecomposition::from_sorted_sample(0, x, 4);
  EXPECT_EQ(s.cuts(), (std::vector<double>{1, 2, 2}));
  EXPECT_EQ(s.owner(1.0), 1);
  EXPECT_EQ(s.owner(2.0), 3);
  EXPECT_TRUE(s.empty(2));
  ExportPlan plan = make_owner_plan(s, x);
  EXPECT_EQ(plan.count(0), 0u);
  EXPECT_EQ(plan.count(1), 1u);
  EXPECT_EQ(plan.count(2), 0u);
  EXPECT_EQ(plan.count(3), 1u);
  // Body 0 (rank 1) is within w = 1.5 of rank 0's slab and of rank 3's; rank 2 is empty.
  EXPECT_EQ(ghost_ranks(s, 1.0, 1.5), (std::vector<int>{0, 3}));
}

TEST(SlabDecomposition, EmptySampleGivesZeroCuts) {
  SlabDecomposition s = SlabDecomposition::from_sorted_sample(0, {}, 3);
  EXPECT_EQ(s.cuts(), (std::vector<double>{0, 0}));
}

//   lo = 0                                   hi = 12
//   (-inf ..... 3)[3 ...... 6)[6 ...... 9)[9 ..... +inf)
TEST(SlabDecomposition, EqualWidths) {
  SlabDecomposition s = SlabDecomposition::equal_width(0, 0.0, 12.0, 4);
  EXPECT_EQ(s.cuts(), (std::vector<double>{3, 6, 9}));
  SlabDecomposition flat = SlabDecomposition::equal_width(0, 2.0, 2.0, 3);
  EXPECT_EQ(flat.cuts(), (std::vector<double>{2, 2}));
  EXPECT_THROW(SlabDecomposition::equal_width(0, 1.0, 0.0, 3), InputError);
}

// Ghosts go to neighbours within the ghost width w = 2, the closed slab counting (distance exactly w):
//
//      rank 0       rank 1          rank 2           rank 3
//   (-inf ..... 0)[0 .......... 10)[10 .......... 20)[20 ...... +inf)
//                  ^1      ^5   ^8 ^9
TEST(HaloPlan, NeighboursWithinTheGhostWidth) {
  SlabDecomposition s(0, {0.0, 10.0, 20.0});
  EXPECT_EQ(ghost_ranks(s, 1.0, 2.0), (std::vector<int>{0}));
  EXPECT_EQ(ghost_ranks(s, 5.0, 2.0), (std::vector<int>{}));
  EXPECT_EQ(ghost_ranks(s, 8.0, 2.0), (std::vector<int>{2}));  // 10 - 8 == w: included
  EXPECT_EQ(ghost_ranks(s, 9.0, 2.0), (std::vector<int>{2}));
  EXPECT_EQ(ghost_ranks(s, 0.0, 2.0), (std::vector<int>{0}));  // on the cut, owned by rank 1
  const std::vector<double> owned = {1.0, 5.0, 8.0, 9.0};
  ExportPlan halo = make_halo_plan(s, 1, owned, 2.0);
  EXPECT_EQ(halo.count(0), 1u);
  EXPECT_EQ(halo.count(1), 0u);
  EXPECT_EQ(halo.count(2), 2u);
  EXPECT_EQ(halo.count(3), 0u);
  EXPECT_EQ(std::vector<std::size_t>(halo.to(2).begin(), halo.to(2).end()), (std::vector<std::size_t>{2, 3}));
  EXPECT_EQ(halo.to(0)[0], 0u);
}

// Slabs thinner than the ghost width: a body is a ghost on every slab within w, not only the
// neighbour's. w = 2.5:
//
//      rank 0     rank 1  rank 2    rank 3
//   (-inf ... 0)[0 .. 1)[1 .. 2)[2 ..... +inf)
//          ^-0.5 ........................ -0.5 + 2.5 = 2.0 reaches rank 3's closed end
TEST(HaloPlan, SlabsThinnerThanTheGhostWidthSendFurther) {
  SlabDecomposition s(0, {0.0, 1.0, 2.0});
  EXPECT_EQ(ghost_ranks(s, -0.5, 2.5), (std::vector<int>{1, 2, 3}));
  EXPECT_EQ(ghost_ranks(s, -0.5, 2.4), (std::vector<int>{1, 2}));
  EXPECT_EQ(ghost_ranks(s, 1.5, 2.5), (std::vector<int>{0, 1, 3}));
  EXPECT_EQ(ghost_ranks(s, 10.0, 100.0), (std::vector<int>{0, 1, 2}));
}

TEST(HaloPlan, RejectsBodiesNotOwned) {
  SlabDecomposition s(0, {0.0});
  const std::vector<double> x = {-1.0, 1.0};
  EXPECT_THROW(make_halo_plan(s, 0, x, 1.0), InputError);
  EXPECT_THROW(make_halo_plan(s, 2, {}, 1.0), UsageError);
  EXPECT_THROW(make_halo_plan(s, 0, {}, std::nan("")), InputError);
}

// The invariant of the halo plan, checked by brute force on random slabs (thin, empty, wide) and
// bodies (many exactly on cuts): for every pair i < j with |x_i - x_j| <= w, the owner of i holds j.
TEST(HaloPlan, OwnerOfEveryCloseBodyHoldsTheOther) {
  std::mt19937_64 rng(2024);
  for (int trial = 0; trial < 200; ++trial) {
    const int ranks = 1 + static_cast<int>(rng() % 9);
    std::uniform_real_distribution<double> u(-10, 10);
    std::vector<double> cuts(static_cast<std::size_t>(ranks - 1));
    for (double& c : cuts) c = (rng() % 4 == 0) ? std::round(u(rng)) : u(rng);
    std::sort(cuts.begin(), cuts.end());
    if (ranks > 2 && rng() % 3 == 0) cuts[1] = cuts[0];  // an empty slab
    SlabDecomposition s(0, cuts);
    const double w = std::uniform_real_distribution<double>(0.01, 6.0)(rng);
    std::vector<double> x(60);
    for (double& v : x) v = (rng() % 5 == 0 && !cuts.empty()) ? cuts[rng() % cuts.size()] : u(rng);
    // Every rank's plan over the bodies it owns.
    std::vector<std::vector<std::size_t>> owned(static_cast<std::size_t>(ranks));
    for (std::size_t i = 0; i < x.size(); ++i) owned[static_cast<std::size_t>(s.owner(x[i]))].push_back(i);
    std::vector<std::vector<bool>> holds(static_cast<std::size_t>(ranks), std::vector<bool>(x.size(), false));
    for (int r = 0; r < ranks; ++r) {
      std::vector<double> xr;
      for (std::size_t i : owned[static_cast<std::size_t>(r)]) {
        xr.push_back(x[i]);
        holds[static_cast<std::size_t>(r)][i] = true;
      }
      ExportPlan halo = make_halo_plan(s, r, xr, w);
      EXPECT_EQ(halo.count(r), 0u);
      for (int q = 0; q < ranks; ++q) {
        for (std::size_t k : halo.to(q))
          holds[static_cast<std::size_t>(q)][owned[static_cast<std::size_t>(r)][k]] = true;
      }
    }
    for (std::size_t i = 0; i < x.size(); ++i) {
      for (std::size_t j = 0; j < x.size(); ++j) {
        if (i == j || std::abs(x[i] - x[j]) > w) continue;
        EXPECT_TRUE(holds[static_cast<std::size_t>(s.owner(x[i]))][j])
            << "trial " << trial << ": body " << j << " at " << x[j] << " missing on the owner of body " << i
            << " at " << x[i] << " (w " << w << ")";
      }
    }
  }
}

TEST(OwnerPlan, GroupsIndicesByOwnerInAscendingOrder) {
  SlabDecomposition s(0, {0.0, 10.0});
  const std::vector<double> x = {15, -1, 5, 0, 10, -3};
  ExportPlan plan = make_owner_plan(s, x);
  ASSERT_EQ(plan.offsets, (std::vector<std::size_t>{0, 2, 4, 6}));
  EXPECT_EQ(plan.rows, (std::vector<std::size_t>{1, 5, 2, 3, 0, 4}));
}

// The quantile selection gives the cuts of the sorted sample, for any rank count (selection up to 64
// ranks, a sort above), with ties and fewer samples than ranks.
TEST(SlabDecomposition, UnsortedSampleGivesTheSortedSamplesCuts) {
  std::mt19937_64 rng(17);
  std::uniform_int_distribution<int> value(0, 50);  // many ties
  for (std::size_t n : {0u, 1u, 3u, 100u, 5000u}) {
    std::vector<double> sample(n);
    for (double& v : sample) v = value(rng);
    std::vector<double> sorted = sample;
    std::sort(sorted.begin(), sorted.end());
    for (int ranks : {1, 2, 3, 7, 64, 65, 200}) {
      EXPECT_EQ(SlabDecomposition::from_sample(0, sample, ranks).cuts(),
                SlabDecomposition::from_sorted_sample(0, sorted, ranks).cuts())
          << n << " samples, " << ranks << " ranks";
    }
  }
}

TEST(SlabAxis, LargestExtentUnlessForced) {
  Bounds b;
  b.lo = {0, 0, 0};
  b.hi = {1, 3, 2};
  EXPECT_EQ(choose_axis(b, -1), 1);
  EXPECT_EQ(choose_axis(b, 2), 2);
  b.hi = {2, 2, 2};
  EXPECT_EQ(choose_axis(b, -1), 0);  // ties: the lowest axis
  EXPECT_THROW(choose_axis(b, 3), UsageError);
  // the words of --axis and --balance are the CLI's (tests/unit/test_cli.cpp)
}

TEST(GhostWidth, TwiceTheLargestRadiusPlusARoundingMargin) {
  EXPECT_GE(ghost_width(1.0, 0.0, 0.0), 2.0);
  EXPECT_EQ(ghost_width(1.0, 100.0, 0.0), 2.0);
  const double eps32 = std::numeric_limits<float>::epsilon();
  EXPECT_GT(ghost_width(1.0, 1000.0, eps32), 2.0 + 1000.0 * eps32);
  EXPECT_LT(ghost_width(1.0, 1000.0, eps32), 2.01);
}

}  // namespace
}  // namespace cg
