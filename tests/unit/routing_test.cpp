// Unit tests of decomposition/routing and decomposition/assemble: the plans and the engine input of
// the distributed run, checked against brute force on seeded random bodies. Pure host code, no MPI.
#include "routing.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "assemble.hpp"

namespace cg {
namespace {

// Random centres along x in [0, 100), radii in [0.5, 1.5), and P-1 sorted random cuts.
struct Bodies {
  HostVector<Vec3<double>> position;
  HostVector<double> radius;
};

Bodies random_bodies(std::size_t n, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> x(0, 100), r(0.5, 1.5);
  Bodies b;
  for (std::size_t i = 0; i < n; ++i) {
    b.position.push_back({x(rng), x(rng), x(rng)});
    b.radius.push_back(r(rng));
  }
  return b;
}

SlabDecomposition random_slabs(int ranks, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> x(0, 100);
  std::vector<double> cuts(static_cast<std::size_t>(ranks - 1));
  for (double& c : cuts) c = x(rng);
  std::sort(cuts.begin(), cuts.end());
  return SlabDecomposition(0, cuts);
}

// route(): each destination's rows in ascending source order, the same for every thread count, and
// the plan as indices equals the plan as records.
TEST(Routing, GroupsByDestinationInSourceOrderWhateverTheThreads) {
  for (unsigned seed : {1u, 2u, 3u}) {
    const std::size_t n = 40000;  // above the one-chunk threshold, so threads split the rows
    const Bodies b = random_bodies(n, seed);
    const SlabDecomposition s = random_slabs(5, seed);
    auto x = [&](std::size_t i) { return b.position[i].x; };
    const ExportPlan plan = route<std::size_t, std::allocator<std::size_t>>(
        n, s.ranks(), 1, to_ghost_ranks(s, x, 3.0), [](std::size_t i) { return i; });
    // brute force
    std::vector<std::vector<std::size_t>> want(5);
    for (std::size_t i = 0; i < n; ++i)
      for (int r = 0; r < 5; ++r)
        if (r != s.owner(x(i)) && !s.empty(r) && s.lower(r) <= x(i) + 3.0 && x(i) - 3.0 <= s.upper(r))
          want[static_cast<std::size_t>(r)].push_back(i);
    for (int r = 0; r < 5; ++r) {
      const auto got = plan.to(r);
      EXPECT_EQ(std::vector<std::size_t>(got.begin(), got.end()), want[static_cast<std::size_t>(r)]) << r;
    }
    for (int threads : {2, 3, 7}) {
      const Exports<BodyRecord> records =
          route<BodyRecord>(n, s.ranks(), threads, to_ghost_ranks(s, x, 3.0), [&](std::size_t i) {
            return BodyRecord{b.position[i], b.radius[i], static_cast<std::int64_t>(i)};
          });
      ASSERT_EQ(records.offsets, plan.offsets) << threads;
      for (std::size_t k = 0; k < plan.total(); ++k)
        ASSERT_EQ(records.rows[k].id, static_cast<std::int64_t>(plan.rows[k])) << threads;
      EXPECT_EQ(records.counts(), (std::vector<std::uint64_t>(plan.counts()))) << threads;
    }
  }
}

TEST(Routing, OwnerPlanIsAPartition) {
  const Bodies b = random_bodies(20000, 4);
  const SlabDecomposition s = random_slabs(4, 4);
  std::vector<double> x(b.position.size());
  for (std::size_t i = 0; i < x.size(); ++i) x[i] = b.position[i].x;
  const ExportPlan plan = make_owner_plan(s, x, 3);
  ASSERT_EQ(plan.total(), x.size());
  std::vector<char> seen(x.size(), 0);
  for (int r = 0; r < 4; ++r) {
    const auto to = plan.to(r);
    EXPECT_TRUE(std::is_sorted(to.begin(), to.end()));
    for (std::size_t i : to) {
      EXPECT_EQ(s.owner(x[i]), r);
      seen[i]++;
    }
  }
  EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), static_cast<std::ptrdiff_t>(x.size()));
  EXPECT_EQ(make_owner_plan(s, x, 1).rows, plan.rows);
}

TEST(Routing, FirstBadIsTheSmallestWhateverTheThreads) {
  std::vector<int> v(50000, 0);
  v[31234] = v[40000] = v[49999] = 1;
  for (int threads : {1, 2, 5})
    EXPECT_EQ(first_bad(v.size(), threads, [&](std::size_t i) { return v[i] != 0; }), 31234u);
  EXPECT_EQ(first_bad(v.size(), 3, [](std::size_t) { return false; }), v.size());
}

// Both ways of assembling a rank's engine input give the same arrays: selected from every row, or
// owned records (grouped by source rank) merged with the ghosts (grouped by source rank) by id.
TEST(Assemble, EveryRowSelectionEqualsOwnedMergedWithGhosts) {
  const int ranks = 4;
  const std::size_t n = 30000;
  const Bodies b = random_bodies(n, 5);
  const SlabDecomposition s = random_slabs(ranks, 5);
  const double width = 3.0;
  auto x = [&](std::size_t i) { return b.position[i].x; };
  auto record = [&](std::size_t i) {
    return BodyRecord{b.position[i], b.radius[i], static_cast<std::int64_t>(i)};
  };
  // own rows: rank q's partition [n·q/P, n·(q+1)/P) routed to the owners
  std::vector<Exports<BodyRecord>> owner_exports;
  for (int q = 0; q < ranks; ++q) {
    const std::size_t lo = n * q / ranks, hi = n * (q + 1) / ranks;
    owner_exports.push_back(route<BodyRecord>(hi - lo, ranks, 2,
                                              to_owner(s, [&](std::size_t i) { return x(lo + i); }),
                                              [&](std::size_t i) { return record(lo + i); }));
  }
  for (int me = 0; me < ranks; ++me) {
    HostVector<BodyRecord> owned;
    for (int q = 0; q < ranks; ++q)
      for (const BodyRecord& r : owner_exports[static_cast<std::size_t>(q)].to(me)) owned.push_back(r);
    // ghosts: every rank's halo exports to `me`, grouped by source
    HostVector<BodyRecord> ghosts;
    std::vector<std::uint64_t> ghost_counts;
    for (int q = 0; q < ranks; ++q) {
      HostVector<BodyRecord> theirs;
      for (int p = 0; p < ranks; ++p)
        for (const BodyRecord& r : owner_exports[static_cast<std::size_t>(p)].to(q)) theirs.push_back(r);
      auto tx = [&](std::size_t i) { return theirs[i].position.x; };
      check_halo_rows(s, q, theirs.size(), tx, width, 2);
      const Exports<BodyRecord> halo = route<BodyRecord>(
          theirs.size(), ranks, 2, to_ghost_ranks(s, tx, width), [&](std::size_t i) { return theirs[i]; });
      ghost_counts.push_back(halo.count(me));
      for (const BodyRecord& r : halo.to(me)) ghosts.push_back(r);
    }
    const EngineInput merged = merge_by_id(owned, ghosts, ghost_counts, 3);
    HostVector<Vec3<double>> p(b.position);
    HostVector<double> r(b.radius);
    const EngineInput selected = select_owned_and_ghosts(std::move(p), std::move(r), s, width, me, 3);
    EXPECT_EQ(selected.owned, merged.owned) << me;
    EXPECT_EQ(selected.ghosts, merged.ghosts) << me;
    ASSERT_EQ(selected.id.size(), merged.id.size()) << me;
    EXPECT_TRUE(std::equal(selected.id.begin(), selected.id.end(), merged.id.begin())) << me;
    EXPECT_TRUE(std::equal(selected.report.begin(), selected.report.end(), merged.report.begin())) << me;
    EXPECT_TRUE(std::equal(selected.radius.begin(), selected.radius.end(), merged.radius.begin())) << me;
    EXPECT_TRUE(std::is_sorted(merged.id.begin(), merged.id.end())) << me;
    for (std::size_t k = 0; k < merged.id.size(); ++k)
      EXPECT_EQ(merged.report[k] == kReportedBit, s.owner(x(static_cast<std::size_t>(merged.id[k]))) == me)
          << me;
  }
}

// One slab: the rows as read are the input, moved, with ids implied.
TEST(Assemble, OneSlabTakesTheRowsAsRead) {
  Bodies b = random_bodies(100, 6);
  const Vec3<double>* data = b.position.data();
  const EngineInput in = select_owned_and_ghosts(std::move(b.position), std::move(b.radius),
                                                 SlabDecomposition::single(0), 1.0, 0, 2);
  EXPECT_TRUE(in.implied());
  EXPECT_EQ(in.owned, 100u);
  EXPECT_EQ(in.ghosts, 0u);
  EXPECT_EQ(in.position.data(), data);
}

TEST(Assemble, AnIdHeldTwiceIsAnInternalError) {
  HostVector<BodyRecord> owned{BodyRecord{{0, 0, 0}, 1, 3}};
  HostVector<BodyRecord> ghosts{BodyRecord{{0, 0, 0}, 1, 3}};
  EXPECT_THROW(merge_by_id(owned, ghosts, {1}, 1), Error);
}

// ---- the ghost rule (GhostRule): a width per body ---------------------------------------------------

// Bodies of radius 0.1 in [0, 100) × [0, 10)², every 500th one of radius 5 (a wide body).
Bodies two_sizes(std::size_t n, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> x(0, 100), y(0, 10);
  Bodies b;
  for (std::size_t i = 0; i < n; ++i) {
    b.position.push_back({x(rng), y(rng), y(rng)});
    b.radius.push_back(i % 500 == 0 ? 5.0 : 0.1);
  }
  return b;
}

Bounds bounds_of(const Bodies& b) { return compute_bounds(BodiesView{b.position, b.radius, {}, {}}); }

TEST(GhostRule, WidthsFollowTheRadii) {
  const GhostRule u = GhostRule::uniform(3.0);
  EXPECT_EQ(u.width(0.1), 3.0);
  EXPECT_EQ(u.width(100.0), 3.0);
  EXPECT_FALSE(u.wide(1e300));
  const Bodies b = two_sizes(10000, 1);
  const GhostRule g = ghost_rule(bounds_of(b), 100, 1e-16);
  EXPECT_NEAR(g.narrow, 4 * (0.1 + 4.9 * 20 / 10000.0), 1e-9);  // 4 × the mean radius
  EXPECT_TRUE(g.wide(5.0));
  EXPECT_FALSE(g.wide(0.1));
  EXPECT_NEAR(g.width(0.1), 0.1 + g.narrow, 1e-12);
  EXPECT_NEAR(g.width(5.0), 10.0, 1e-12);
  EXPECT_EQ(g.wide_bit(5.0), kWideBit);
  // radii within 4x of their mean: nobody is wide, every body's width r + r_max (below 2·r_max)
  const Bodies c = random_bodies(1000, 2);
  const GhostRule h = ghost_rule(bounds_of(c), 100, 1e-16);
  EXPECT_EQ(h.narrow, bounds_of(c).r_max);
  EXPECT_FALSE(h.wide(bounds_of(c).r_max));
}

// The invariant the run relies on: for every contacting pair, the owner of its anchor (bodies.hpp:
// the smaller id, or the narrow body of a wide and a narrow one) holds the other body, owned or as a
// ghost of the per-body halo plan — and the narrow bodies' halos are far smaller than 2·r_max's.
TEST(GhostRule, TheAnchorsOwnerHoldsEveryPartner) {
  const int ranks = 5;
  const std::size_t n = 20000;
  const Bodies b = two_sizes(n, 3);
  const SlabDecomposition s = random_slabs(ranks, 3);
  const GhostRule g = ghost_rule(bounds_of(b), 100, 1e-16);
  std::vector<double> x(n), r(n);
  for (std::size_t i = 0; i < n; ++i) x[i] = b.position[i].x, r[i] = b.radius[i];
  // held[q]: the ids rank q holds (its owned bodies and the halo plans' ghosts to it)
  std::vector<std::vector<char>> held(ranks, std::vector<char>(n, 0));
  std::uint64_t ghosts = 0, uniform_ghosts = 0;
  for (int q = 0; q < ranks; ++q) {
    std::vector<std::size_t> rows;
    std::vector<double> xq, rq;
    for (std::size_t i = 0; i < n; ++i)
      if (s.owner(x[i]) == q) {
        rows.push_back(i);
        xq.push_back(x[i]);
        rq.push_back(r[i]);
      }
    for (std::size_t i : rows) held[q][i] = 1;
    const ExportPlan plan = make_halo_plan(s, q, xq, rq, g, 2);
    for (int to = 0; to < ranks; ++to)
      for (std::size_t k : plan.to(to)) held[to][rows[k]] = 1;
    ghosts += plan.total();
    uniform_ghosts += make_halo_plan(s, q, xq, ghost_width(5.0, 100, 1e-16), 2).total();
  }
  std::uint64_t pairs = 0, across = 0;
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = i + 1; j < n; ++j) {
      const Vec3<double> d = b.position[i] - b.position[j];
      const double sum = r[i] + r[j];
      if (d.x * d.x + d.y * d.y + d.z * d.z > sum * sum) continue;
      ++pairs;
      const bool wi = g.wide(r[i]), wj = g.wide(r[j]);
      const std::size_t anchor = wi != wj ? (wi ? j : i) : i, other = anchor == i ? j : i;
      const int owner = s.owner(x[anchor]);
      across += s.owner(x[other]) != owner;
      ASSERT_TRUE(held[owner][other]) << "pair " << i << " " << j;
    }
  EXPECT_GT(pairs, 1000u);
  EXPECT_GT(across, 10u);                 // pairs across cuts exercise the halo
  EXPECT_LT(5 * ghosts, uniform_ghosts);  // narrow halos: r + 0.44 instead of 10
}

TEST(Assemble, WideBitsMarkTheRulesWideBodies) {
  const Bodies b = two_sizes(5000, 4);
  const SlabDecomposition s = random_slabs(3, 4);
  const GhostRule g = ghost_rule(bounds_of(b), 100, 1e-16);
  HostVector<Vec3<double>> p(b.position);
  HostVector<double> r(b.radius);
  const EngineInput in = select_owned_and_ghosts(std::move(p), std::move(r), s, g, 1, 2);
  std::uint64_t wide = 0;
  for (std::size_t k = 0; k < in.id.size(); ++k) {
    const auto i = static_cast<std::size_t>(in.id[k]);
    EXPECT_EQ(in.report[k] & kWideBit, g.wide_bit(b.radius[i])) << k;
    EXPECT_EQ((in.report[k] & kReportedBit) != 0, s.owner(b.position[i].x) == 1) << k;
    wide += (in.report[k] & kWideBit) != 0;
  }
  EXPECT_GT(wide, 0u);
}

TEST(Routing, HaloPreconditions) {
  const SlabDecomposition s(0, {10.0});
  std::vector<double> x{1, 2, 11};
  auto at = [&](std::size_t i) { return x[i]; };
  EXPECT_THROW(check_halo_rows(s, 0, x.size(), at, 1.0, 1), InputError);
  EXPECT_NO_THROW(check_halo_rows(s, 0, 2, at, 1.0, 1));
  EXPECT_THROW(check_halo_rows(s, 0, 2, at, -1.0, 1), InputError);
}

}  // namespace
}  // namespace cg
