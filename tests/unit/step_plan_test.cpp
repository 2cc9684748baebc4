// Unit tests of decomposition/step_plan and step_bodies: the roles of a rank's rows in the resident
// steps and its halo, against brute force on seeded random bodies; the two engines of every rank
// together find each contact exactly once. Pure host code, no MPI.
#include "step_plan.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <set>
#include <vector>

#include "core/broad.hpp"
#include "step_bodies.hpp"

namespace cg {
namespace {

std::vector<double> random_coordinates(std::size_t n, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> x(0, 100);
  std::vector<double> v(n);
  for (double& c : v) c = x(rng);
  return v;
}

// P-1 sorted random cuts, some of them equal (empty slabs) or closer than the ghost width.
SlabDecomposition random_slabs(int ranks, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> x(0, 100);
  std::vector<double> cuts(static_cast<std::size_t>(ranks - 1));
  for (double& c : cuts) c = x(rng);
  if (cuts.size() > 2) cuts[1] = cuts[0];
  std::sort(cuts.begin(), cuts.end());
  return SlabDecomposition(0, cuts);
}

// The ranks other than owner(x) with a non-empty slab within w of x (brute force).
std::vector<int> ghost_ranks(const SlabDecomposition& s, double x, double w) {
  std::vector<int> r;
  for (int q = 0; q < s.ranks(); ++q)
    if (q != s.owner(x) && !s.empty(q) && s.lower(q) <= x + w && x - w <= s.upper(q)) r.push_back(q);
  return r;
}

// Roles and halo against brute force, for every rank of random slabs, whatever the threads.
TEST(StepPlan, RolesAndHaloAreTheRoutingRules) {
  std::mt19937_64 rng(41);
  for (int trial = 0; trial < 6; ++trial) {
    const int ranks = 1 + trial % 5;
    const std::size_t n = trial < 3 ? 3000 : 40000;  // above the one-chunk threshold: threads split
    const std::vector<double> x = random_coordinates(n, rng);
    const SlabDecomposition s = random_slabs(ranks, rng);
    const double w = trial == 5 ? 30.0 : 2.5;  // thin slabs: ghosts from further ranks
    for (int self = 0; self < ranks; ++self) {
      const StepPlan plan = make_step_plan(s, self, x, w, 1);
      ASSERT_EQ(plan.role.size(), n);
      std::vector<std::vector<std::size_t>> want(static_cast<std::size_t>(ranks));
      std::vector<std::size_t> owned, boundary;
      for (std::size_t i = 0; i < n; ++i) {
        const std::vector<int> g = ghost_ranks(s, x[i], w);
        const RowRole role = s.owner(x[i]) != self ? RowRole::ghost
                             : g.empty()           ? RowRole::interior
                                                   : RowRole::boundary;
        ASSERT_EQ(plan.role[i], role)
            << "row " << i << " of rank " << self << ": " << to_string(plan.role[i]);
        if (role == RowRole::ghost) continue;
        owned.push_back(i);
        if (role == RowRole::boundary) boundary.push_back(i);
        for (int q : g) want[static_cast<std::size_t>(q)].push_back(i);
      }
      EXPECT_EQ(plan.owned, owned.size());
      EXPECT_EQ(plan.boundary, boundary);
      EXPECT_EQ(plan.count(RowRole::interior) + plan.count(RowRole::boundary), owned.size());
      for (int q = 0; q < ranks; ++q) {
        const auto got = plan.halo.to(q);
        EXPECT_EQ(std::vector<std::size_t>(got.begin(), got.end()), want[static_cast<std::size_t>(q)])
            << "to rank " << q << " from " << self;
      }
      const StepPlan threaded = make_step_plan(s, self, x, w, 3);
      EXPECT_EQ(threaded.role, plan.role);
      EXPECT_EQ(threaded.halo.offsets, plan.halo.offsets);
      EXPECT_EQ(threaded.halo.rows, plan.halo.rows);
    }
  }
}

// Every rank's two engines, as the steps run them: A all pairs of the owned rows, B the boundary
// rows + the ghosts the others' halos deliver (ascending id), reporting a pair when its first by id is
// owned and not both are boundary rows. Every pair within the ghost width (a superset of the
// contacts) is then found exactly once over all ranks, whatever the slabs.
TEST(StepPlan, TheTwoEnginesOfAllRanksFindEveryPairOnce) {
  std::mt19937_64 rng(42);
  for (int trial = 0; trial < 8; ++trial) {
    const int ranks = 1 + trial % 4;
    const std::size_t n = 700;
    std::vector<double> x = random_coordinates(n, rng);
    const SlabDecomposition s = random_slabs(ranks, rng);
    const double w = trial % 2 ? 1.5 : 9.0;
    // ids: a random permutation, so id order is not coordinate order
    std::vector<std::int64_t> id(n);
    std::iota(id.begin(), id.end(), 0);
    std::shuffle(id.begin(), id.end(), rng);
    std::vector<std::vector<std::size_t>> held(static_cast<std::size_t>(ranks));  // rows by id
    std::vector<std::size_t> by_id(n);
    for (std::size_t i = 0; i < n; ++i) by_id[static_cast<std::size_t>(id[i])] = i;
    for (std::size_t k = 0; k < n; ++k)
      held[static_cast<std::size_t>(s.owner(x[by_id[k]]))].push_back(by_id[k]);
    std::vector<StepPlan> plans;
    for (int p = 0; p < ranks; ++p) {
      std::vector<double> xs;
      for (std::size_t i : held[static_cast<std::size_t>(p)]) xs.push_back(x[i]);
      plans.push_back(make_step_plan(s, p, xs, w));
      EXPECT_EQ(plans.back().count(RowRole::ghost), 0u);
    }
    std::map<std::pair<std::int64_t, std::int64_t>, int> found;
    auto report = [&](std::size_t i, std::size_t j) {
      if (std::abs(x[i] - x[j]) > w) return;
      ++found[{std::min(id[i], id[j]), std::max(id[i], id[j])}];
    };
    for (int p = 0; p < ranks; ++p) {
      const auto& rows = held[static_cast<std::size_t>(p)];
      const StepPlan& plan = plans[static_cast<std::size_t>(p)];
      for (std::size_t a = 0; a < rows.size(); ++a)  // engine A
        for (std::size_t b = a + 1; b < rows.size(); ++b) report(rows[a], rows[b]);
      // engine B: the boundary rows and the ghosts sent to p (grouped by source, as delivered)
      std::vector<std::int64_t> boundary_ids, ghost_ids;
      std::vector<std::size_t> ghost_rows;
      for (std::size_t k : plan.boundary) boundary_ids.push_back(id[rows[k]]);
      for (int q = 0; q < ranks; ++q)
        for (std::size_t k : plans[static_cast<std::size_t>(q)].halo.to(p)) {
          ghost_rows.push_back(held[static_cast<std::size_t>(q)][k]);
          ghost_ids.push_back(id[ghost_rows.back()]);
        }
      const BoundaryRows b = merge_boundary_rows(boundary_ids, ghost_ids);
      std::vector<std::size_t> row_of(b.size());
      std::vector<std::uint8_t> mask(b.size());
      for (std::size_t k = 0; k < plan.boundary.size(); ++k) {
        row_of[b.of_boundary[k]] = rows[plan.boundary[k]];
        mask[b.of_boundary[k]] = kReportedBit | kPairedBit;
      }
      for (std::size_t g = 0; g < ghost_rows.size(); ++g) row_of[b.of_ghost[g]] = ghost_rows[g];
      for (std::size_t r = 1; r < b.size(); ++r) ASSERT_LT(id[row_of[r - 1]], id[row_of[r]]);
      for (std::size_t a = 0; a < b.size(); ++a)
        for (std::size_t c = a + 1; c < b.size(); ++c)
          if ((mask[a] & kReportedBit) && !((mask[a] & kPairedBit) && (mask[c] & kPairedBit)))
            report(row_of[a], row_of[c]);
    }
    std::size_t pairs = 0;
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = i + 1; j < n; ++j)
        if (std::abs(x[i] - x[j]) <= w) {
          ++pairs;
          const auto it = found.find({std::min(id[i], id[j]), std::max(id[i], id[j])});
          ASSERT_TRUE(it != found.end())
              << "pair " << id[i] << ", " << id[j] << " missed at " << ranks << " ranks";
          ASSERT_EQ(it->second, 1) << "pair " << id[i] << ", " << id[j] << " found twice";
        }
    EXPECT_EQ(found.size(), pairs);
    EXPECT_GT(pairs, n);
  }
}

// ---- a ghost width per body (GhostRule): large bodies to every slab they reach, small halos small ----

// Radii of a mixed scene: most small (0.2 … 0.4), every `every`-th large (`large`), the rule of the
// run (ghost_rule) over their bounds, with a margin standing for the rounding and the skin.
struct Sized {
  std::vector<double> x, r;
  GhostRule rule;
};
Sized sized(std::size_t n, double large, std::mt19937_64& rng, std::size_t every = 97, double reach = 0.05) {
  Sized s;
  s.x = random_coordinates(n, rng);
  std::uniform_real_distribution<double> small(0.2, 0.4);
  Bounds b;
  b.count = n;
  for (std::size_t i = 0; i < n; ++i) {
    s.r.push_back(i % every == 5 ? large : small(rng));
    b.r_max = std::max(b.r_max, s.r.back());
    b.r_sum[0] += s.r.back();
  }
  b.lo = {0, 0, 0};
  b.hi = {100, 100, 100};
  s.rule = ghost_rule(b, 100, 1e-16, reach);
  return s;
}

// Roles and halo against brute force with each row's own width, whatever the threads; the owned rows
// a wide ghost may touch become boundary rows (add_wide_partners) and go nowhere.
TEST(StepPlan, PerBodyRolesHaloAndWidePartners) {
  std::mt19937_64 rng(43);
  for (int trial = 0; trial < 6; ++trial) {
    const int ranks = 2 + trial % 3;
    const std::size_t n = trial < 3 ? 3000 : 40000;
    const Sized b = sized(n, trial % 2 ? 6.0 : 2.5, rng);
    ASSERT_TRUE(b.rule.wide(b.rule.narrow * 1.01) && !b.rule.wide(0.4));
    const SlabDecomposition s = random_slabs(ranks, rng);
    std::vector<double> wide_x, wide_r;  // a wide ghost set: every wide body another rank owns
    std::size_t all_partners = 0;
    for (int self = 0; self < ranks; ++self) {
      std::vector<double> xs, rs;
      wide_x.clear();
      wide_r.clear();
      for (std::size_t i = 0; i < n; ++i) {
        if (s.owner(b.x[i]) == self) {
          xs.push_back(b.x[i]);
          rs.push_back(b.r[i]);
        } else if (b.rule.wide(b.r[i])) {
          wide_x.push_back(b.x[i]);
          wide_r.push_back(b.r[i]);
        }
      }
      StepPlan plan = make_step_plan(s, self, xs, rs, b.rule, 1);
      const StepPlan threaded = make_step_plan(s, self, xs, rs, b.rule, 3);
      EXPECT_EQ(threaded.role, plan.role);
      EXPECT_EQ(threaded.halo.rows, plan.halo.rows);
      std::vector<std::vector<std::size_t>> want(static_cast<std::size_t>(ranks));
      std::vector<std::size_t> boundary, partners;
      for (std::size_t k = 0; k < xs.size(); ++k) {
        const std::vector<int> g = ghost_ranks(s, xs[k], b.rule.width(rs[k]));
        ASSERT_EQ(plan.role[k], g.empty() ? RowRole::interior : RowRole::boundary) << "row " << k;
        for (int q : g) want[static_cast<std::size_t>(q)].push_back(k);
        bool touched = false;
        for (std::size_t w = 0; w < wide_x.size(); ++w)
          touched = touched || std::abs(xs[k] - wide_x[w]) <= rs[k] + wide_r[w] + b.rule.margin;
        if (!g.empty() || touched) boundary.push_back(k);
        if (g.empty() && touched) partners.push_back(k);
      }
      for (int q = 0; q < ranks; ++q) {
        const auto got = plan.halo.to(q);
        EXPECT_EQ(std::vector<std::size_t>(got.begin(), got.end()), want[static_cast<std::size_t>(q)]);
      }
      const ExportPlan halo = plan.halo;
      StepPlan threaded_partners = threaded;
      EXPECT_EQ(add_wide_partners(plan, xs, rs, wide_x, wide_r, b.rule, 1), partners.size());
      add_wide_partners(threaded_partners, xs, rs, wide_x, wide_r, b.rule, 4);
      EXPECT_EQ(plan.boundary, boundary) << "rank " << self << " of " << ranks;
      EXPECT_EQ(threaded_partners.boundary, boundary);
      EXPECT_EQ(plan.halo.rows, halo.rows);  // the partners are sent nowhere
      all_partners += partners.size();
    }
    if (trial % 2) {  // large bodies of radius 6
      EXPECT_GT(all_partners, 0u) << "trial " << trial;
    }
  }
}

// A small body's ghosts do not grow with the largest radius: four large bodies among 20 000 small ones,
// of radius 2, 8 or 40. A small body's width is r + narrow (kLevelsSpread × the mean radius, which the
// large ones move by under 3 %), so the small rows' halo stays the same set but for a few rows at its
// edge, while the large bodies reach further; one width for all (2·r_max) sends far more.
TEST(StepPlan, SmallBodysGhostsDoNotGrowWithTheLargestRadius) {
  const SlabDecomposition s = SlabDecomposition::equal_width(0, 0, 100, 8);
  std::vector<std::vector<std::size_t>> small_to;  // per large radius: the small rows' halo, flattened
  std::vector<std::size_t> large_sent, uniform_sent;
  for (const double large : {2.0, 8.0, 40.0}) {
    std::mt19937_64 rng(44);  // the same bodies but for the large radius
    const Sized b = sized(20000, large, rng, 5000);
    std::vector<std::size_t> small, total_large;
    std::size_t sent_large = 0, sent_uniform = 0;
    for (int self = 0; self < 8; ++self) {
      std::vector<double> xs, rs;
      std::vector<std::size_t> rows;
      for (std::size_t i = 0; i < b.x.size(); ++i)
        if (s.owner(b.x[i]) == self) {
          xs.push_back(b.x[i]);
          rs.push_back(b.r[i]);
          rows.push_back(i);
        }
      const StepPlan plan = make_step_plan(s, self, xs, rs, b.rule);
      for (int q = 0; q < 8; ++q)
        for (std::size_t k : plan.halo.to(q)) {
          if (b.rule.wide(rs[k])) {
            ++sent_large;
          } else {
            small.push_back(rows[k] * 8 + static_cast<std::size_t>(q));
          }
        }
      const double uniform = 2 * large + b.rule.margin;
      sent_uniform += make_step_plan(s, self, xs, uniform).halo.total();
    }
    std::sort(small.begin(), small.end());
    small_to.push_back(small);
    large_sent.push_back(sent_large);
    uniform_sent.push_back(sent_uniform);
  }
  ASSERT_GT(small_to[0].size(), 1000u);
  for (std::size_t k = 1; k < 3; ++k) {
    EXPECT_TRUE(std::includes(small_to[k].begin(), small_to[k].end(), small_to[0].begin(), small_to[0].end()))
        << "large radius #" << k;
    EXPECT_LT(double(small_to[k].size()), 1.03 * double(small_to[0].size())) << "large radius #" << k;
  }
  EXPECT_LT(large_sent[0], large_sent[1]);  // a large body reaches every slab within r + r_max
  EXPECT_LT(large_sent[1], large_sent[2]);
  EXPECT_GE(large_sent[2], 4u * 5);  // radius 40 over slabs 12.5 wide: most other slabs
  EXPECT_LT(small_to[0].size() + large_sent[0], uniform_sent[0]);
  for (std::size_t k = 1; k < 3; ++k)
    EXPECT_LT(3 * (small_to[k].size() + large_sent[k]), uniform_sent[k]) << "large radius #" << k;
}

// Every rank's two engines with a width per body, as the steps run them: B's mask with kWideBit on the
// wide rows and the owned rows a wide ghost may touch among the boundary rows; B reports a pair by
// core/broad.hpp's pair_reported (the anchor: the narrow body of a wide and a narrow one, else the
// smaller id). Every pair within r_i + r_j + margin (a superset of the contacts) is then found exactly
// once over all ranks.
TEST(StepPlan, TheTwoEnginesFindEveryPairOnceWithWidthsPerBody) {
  std::mt19937_64 rng(45);
  for (int trial = 0; trial < 8; ++trial) {
    const int ranks = 1 + trial % 4;
    const std::size_t n = 1500;
    const Sized b = sized(n, trial % 2 ? 9.0 : 3.0, rng);
    const SlabDecomposition s = random_slabs(ranks, rng);
    std::vector<std::int64_t> id(n);
    std::iota(id.begin(), id.end(), 0);
    std::shuffle(id.begin(), id.end(), rng);
    std::vector<std::size_t> by_id(n);
    for (std::size_t i = 0; i < n; ++i) by_id[static_cast<std::size_t>(id[i])] = i;
    std::vector<std::vector<std::size_t>> held(static_cast<std::size_t>(ranks));  // rows by id
    for (std::size_t k = 0; k < n; ++k)
      held[static_cast<std::size_t>(s.owner(b.x[by_id[k]]))].push_back(by_id[k]);
    auto near = [&](std::size_t i, std::size_t j) {
      return std::abs(b.x[i] - b.x[j]) <= b.r[i] + b.r[j] + b.rule.margin;
    };
    std::vector<StepPlan> plans;
    for (int p = 0; p < ranks; ++p) {
      std::vector<double> xs, rs;
      for (std::size_t i : held[static_cast<std::size_t>(p)]) xs.push_back(b.x[i]), rs.push_back(b.r[i]);
      plans.push_back(make_step_plan(s, p, xs, rs, b.rule));
    }
    std::map<std::pair<std::int64_t, std::int64_t>, int> found;
    auto report = [&](std::size_t i, std::size_t j) {
      if (near(i, j)) ++found[{std::min(id[i], id[j]), std::max(id[i], id[j])}];
    };
    std::size_t ghosts = 0;
    for (int p = 0; p < ranks; ++p) {
      const auto& rows = held[static_cast<std::size_t>(p)];
      StepPlan& plan = plans[static_cast<std::size_t>(p)];
      for (std::size_t a = 0; a < rows.size(); ++a)  // engine A
        for (std::size_t c = a + 1; c < rows.size(); ++c) report(rows[a], rows[c]);
      std::vector<std::size_t> ghost_rows;
      std::vector<std::int64_t> ghost_ids;
      std::vector<double> wide_x, wide_r, xs, rs;
      for (int q = 0; q < ranks; ++q)
        for (std::size_t k : plans[static_cast<std::size_t>(q)].halo.to(p)) {
          const std::size_t i = held[static_cast<std::size_t>(q)][k];
          ghost_rows.push_back(i);
          ghost_ids.push_back(id[i]);
          if (b.rule.wide(b.r[i])) wide_x.push_back(b.x[i]), wide_r.push_back(b.r[i]);
        }
      ghosts += ghost_rows.size();
      for (std::size_t i : rows) xs.push_back(b.x[i]), rs.push_back(b.r[i]);
      add_wide_partners(plan, xs, rs, wide_x, wide_r, b.rule);
      std::vector<std::int64_t> boundary_ids;
      for (std::size_t k : plan.boundary) boundary_ids.push_back(id[rows[k]]);
      const BoundaryRows br = merge_boundary_rows(boundary_ids, ghost_ids);
      std::vector<std::size_t> row_of(br.size());
      std::vector<std::uint8_t> mask(br.size());
      for (std::size_t k = 0; k < plan.boundary.size(); ++k) {
        const std::size_t i = rows[plan.boundary[k]];
        row_of[br.of_boundary[k]] = i;
        mask[br.of_boundary[k]] = kReportedBit | kPairedBit | b.rule.wide_bit(b.r[i]);
      }
      for (std::size_t g = 0; g < ghost_rows.size(); ++g) {
        row_of[br.of_ghost[g]] = ghost_rows[g];
        mask[br.of_ghost[g]] = b.rule.wide_bit(b.r[ghost_rows[g]]);
      }
      for (std::size_t a = 0; a < br.size(); ++a)  // engine B
        for (std::size_t c = a + 1; c < br.size(); ++c)
          if (pair_reported(mask.data(), static_cast<std::uint32_t>(a), static_cast<std::uint32_t>(c)))
            report(row_of[a], row_of[c]);
    }
    std::size_t pairs = 0, wide_pairs = 0;
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = i + 1; j < n; ++j)
        if (near(i, j)) {
          ++pairs;
          wide_pairs += b.rule.wide(b.r[i]) != b.rule.wide(b.r[j]);
          const auto it = found.find({std::min(id[i], id[j]), std::max(id[i], id[j])});
          ASSERT_TRUE(it != found.end()) << "pair " << id[i] << ", " << id[j] << " missed at " << ranks
                                         << " ranks (radii " << b.r[i] << ", " << b.r[j] << ")";
          ASSERT_EQ(it->second, 1) << "pair " << id[i] << ", " << id[j] << " found twice";
        }
    EXPECT_EQ(found.size(), pairs);
    EXPECT_GT(wide_pairs, 100u);
    if (ranks > 1) {
      EXPECT_GT(ghosts, 0u);
    }
  }
}

// The plan of the rows outside the interior band (the step loop's, listed where the rows are) is the
// plan of every row, bit for bit: roles, owned count, boundary rows and halo, for a rule per body and
// one width for all, slabs some empty, rows owned elsewhere; and a band too narrow fails the check.
TEST(StepPlan, ThePlanOfTheRowsOutsideTheBandIsThePlanOfAll) {
  std::mt19937_64 rng(45);
  std::size_t candidates = 0, rows = 0;
  for (int trial = 0; trial < 6; ++trial) {
    const int ranks = 2 + trial % 3;
    const Sized b = sized(trial < 3 ? 3000 : 20000, trial % 2 ? 6.0 : 2.5, rng);
    const SlabDecomposition s = random_slabs(ranks, rng);
    for (const bool per_body : {true, false}) {
      const GhostRule rule = per_body ? b.rule : GhostRule::uniform(2 * 6.0 + 0.1);
      const double r_max = *std::max_element(b.r.begin(), b.r.end());
      for (int self = 0; self < ranks; ++self) {
        // this rank's rows: its own, and a few that left it (ghost rows)
        std::vector<double> xs, rs;
        for (std::size_t i = 0; i < b.x.size(); ++i)
          if (s.owner(b.x[i]) == self || i % 501 == 0) {
            xs.push_back(b.x[i]);
            rs.push_back(b.r[i]);
          }
        const StepPlan all = per_body ? make_step_plan(s, self, xs, rs, rule, 2)
                                      : make_step_plan(s, self, xs, rule.narrow_reach, 2);
        const Band band = interior_band(s, self, rule.max_width(r_max));
        std::vector<std::size_t> outside;
        std::vector<double> ox, orad;
        for (std::size_t k = 0; k < xs.size(); ++k)
          if (!(xs[k] > band.lo && xs[k] < band.hi)) {
            outside.push_back(k);
            ox.push_back(xs[k]);
            orad.push_back(rs[k]);
          }
        const StepPlan of = make_step_plan_of(s, self, xs.size(), outside, ox, orad, rule, 3);
        EXPECT_EQ(of.role, all.role) << "trial " << trial << " rank " << self;
        EXPECT_EQ(of.owned, all.owned);
        EXPECT_EQ(of.boundary, all.boundary);
        EXPECT_EQ(of.halo.offsets, all.halo.offsets);
        EXPECT_EQ(of.halo.rows, all.halo.rows);
        candidates += outside.size();
        rows += xs.size();
        // the band without its width: a boundary row left out is an interior row
        if (!all.boundary.empty()) {
          std::vector<std::size_t> fewer;
          std::vector<double> fx, fr;
          for (std::size_t j = 0; j < outside.size(); ++j)
            if (outside[j] != all.boundary.front()) {
              fewer.push_back(outside[j]);
              fx.push_back(ox[j]);
              fr.push_back(orad[j]);
            }
          EXPECT_NE(make_step_plan_of(s, self, xs.size(), fewer, fx, fr, rule, 1).boundary, all.boundary);
        }
      }
    }
  }
  EXPECT_LT(candidates, rows);  // the band leaves rows out
  const SlabDecomposition s(0, {10.0});
  EXPECT_THROW(make_step_plan_of(s, 0, 4, std::vector<std::size_t>{2, 1}, std::vector<double>{1, 2},
                                 std::vector<double>{1, 1}, GhostRule::uniform(1)),
               UsageError);
}

TEST(StepPlan, MergesBoundaryRowsAndGhostsById) {
  const std::vector<std::int64_t> boundary{2, 5, 9, 40};
  const std::vector<std::int64_t> ghosts{7, 30, 1, 3, 41};  // two sources: [7, 30], [1, 3, 41]
  const BoundaryRows r = merge_boundary_rows(boundary, ghosts);
  EXPECT_EQ(r.of_boundary, (std::vector<std::size_t>{1, 3, 5, 7}));
  EXPECT_EQ(r.of_ghost, (std::vector<std::size_t>{4, 6, 0, 2, 8}));
  EXPECT_EQ(r.size(), 9u);
  EXPECT_THROW(merge_boundary_rows(boundary, std::vector<std::int64_t>{5}), Error);
  EXPECT_THROW(merge_boundary_rows(std::vector<std::int64_t>{3, 2}, {}), Error);
}

// The merge in parts over many rows: the rows of a plain merge by id for any number of threads, with
// the ghosts in one run, in three runs and shuffled, and an id held twice found at any place
// (within a part, at a seam between parts, a ghost twice).
TEST(StepPlan, MergesBoundaryRowsInPartsAsOneMerge) {
  std::mt19937_64 rng(3607);
  for (int trial = 0; trial < 12; ++trial) {
    const std::size_t n = 70000 + rng() % 90000;
    std::vector<std::int64_t> ids(2 * n);
    std::iota(ids.begin(), ids.end(), std::int64_t(0));
    std::shuffle(ids.begin(), ids.end(), rng);
    const std::size_t nb = trial == 0 ? 0 : trial == 1 ? n : n / 3 + rng() % (n / 2);
    std::vector<std::int64_t> boundary(ids.begin(), ids.begin() + static_cast<std::ptrdiff_t>(nb)),
        ghosts(ids.begin() + static_cast<std::ptrdiff_t>(nb), ids.begin() + static_cast<std::ptrdiff_t>(n));
    std::sort(boundary.begin(), boundary.end());
    const int runs = trial % 3;  // 0: one run, 1: three runs, 2: shuffled
    if (runs == 2) {
      std::shuffle(ghosts.begin(), ghosts.end(), rng);
    } else {
      std::sort(ghosts.begin(), ghosts.end());
      if (runs == 1 && ghosts.size() > 3) {  // three sources' runs, each ascending
        std::vector<std::int64_t> a, b, c;
        for (const std::int64_t g : ghosts) (g % 3 == 0 ? a : g % 3 == 1 ? b : c).push_back(g);
        ghosts = a;
        ghosts.insert(ghosts.end(), b.begin(), b.end());
        ghosts.insert(ghosts.end(), c.begin(), c.end());
      }
    }
    // the reference: every id's row in the sorted union
    std::vector<std::int64_t> all(boundary);
    all.insert(all.end(), ghosts.begin(), ghosts.end());
    std::sort(all.begin(), all.end());
    auto row_of = [&](std::int64_t id) {
      return static_cast<std::size_t>(std::lower_bound(all.begin(), all.end(), id) - all.begin());
    };
    for (const int threads : {1, 4, 7}) {
      const BoundaryRows r = merge_boundary_rows(boundary, ghosts, threads);
      ASSERT_EQ(r.size(), all.size());
      for (std::size_t k = 0; k < boundary.size(); ++k)
        ASSERT_EQ(r.of_boundary[k], row_of(boundary[k])) << "trial " << trial << " threads " << threads;
      for (std::size_t g = 0; g < ghosts.size(); ++g)
        ASSERT_EQ(r.of_ghost[g], row_of(ghosts[g])) << "trial " << trial << " threads " << threads;
    }
    if (boundary.empty() || ghosts.empty()) continue;
    // an id held twice: a ghost taking a boundary row's id at any place, or a ghost's id twice
    for (const std::size_t at : {std::size_t(0), boundary.size() / 2, boundary.size() - 1}) {
      std::vector<std::int64_t> twice = ghosts;
      twice[rng() % twice.size()] = boundary[at];
      if (runs != 2) std::sort(twice.begin(), twice.end());
      for (const int threads : {1, 4, 7}) EXPECT_THROW(merge_boundary_rows(boundary, twice, threads), Error);
    }
    std::vector<std::int64_t> twice = ghosts;
    twice.push_back(ghosts[rng() % ghosts.size()]);
    for (const int threads : {1, 4, 7}) EXPECT_THROW(merge_boundary_rows(boundary, twice, threads), Error);
  }
}

// A scene of spheres alone carries each body's file centre (24 bytes), with ellipsoids the whole pose
// (56): the drift moves either to drifted_position, the spin needs the pose.
TEST(StepBodies, FilePosesOfSpheresCarryTheCentreAlone) {
  StepBodies b = sized_step_bodies(3, false);
  for (std::size_t k = 0; k < 3; ++k) {
    b.id[k] = std::int64_t(10 + k);
    b.position[k] = {double(k), 2.0 * double(k), -1.0};
    b.radius[k] = 0.5;
  }
  const StepBodies start = b;
  attach_file_poses(b, false, 2);
  EXPECT_EQ(b.state_bytes, 24u);
  ASSERT_EQ(b.state.size(), 3u * 24u);
  StepMotion m;
  m.drift = 0.125;
  for (const int step : {1, 4}) {
    const Moved moved = move_bodies(b, m, step, 2);
    EXPECT_TRUE(moved.positions);
    for (std::size_t k = 0; k < 3; ++k) {
      const Vec3<double> want = drifted_position(b.id[k], start.position[k], m.drift, step);
      EXPECT_EQ(b.position[k].x, want.x);
      EXPECT_EQ(b.position[k].y, want.y);
      EXPECT_EQ(b.position[k].z, want.z);
    }
  }
  StepBodies with = start;
  attach_file_poses(with, true, 1);  // another rank's ellipsoids: the whole pose, the identity here
  EXPECT_EQ(with.state_bytes, sizeof(FilePose));
  EXPECT_EQ(move_bodies(with, m, 2, 1).positions, true);
  EXPECT_EQ(with.position[1].x, drifted_position(11, start.position[1], m.drift, 2).x);
  b.state_bytes = 8;  // no pose at all
  EXPECT_THROW(move_bodies(b, m, 1, 1), Error);
}

TEST(StepPlan, RefusesBadWidthsAndCoordinates) {
  const SlabDecomposition s(0, {50.0});
  const std::vector<double> x{1, 2, 60};
  EXPECT_THROW(make_step_plan(s, 0, x, -1), InputError);
  EXPECT_THROW(make_step_plan(s, 0, x, std::numeric_limits<double>::infinity()), InputError);
  EXPECT_THROW(make_step_plan(s, 2, x, 1), UsageError);
  const std::vector<double> bad{1, std::numeric_limits<double>::quiet_NaN()};
  EXPECT_THROW(make_step_plan(s, 0, bad, 1), InputError);
  const StepPlan one = make_step_plan(SlabDecomposition::single(0), 0, x, 5);
  EXPECT_EQ(one.count(RowRole::interior), 3u);  // one rank: no other slab, no halo
  EXPECT_EQ(one.halo.total(), 0u);
  const std::vector<double> r{0.5, 0.5, 0.5};
  GhostRule bad_rule = GhostRule::uniform(1);
  bad_rule.wide_reach = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(make_step_plan(s, 0, x, r, bad_rule), InputError);
  EXPECT_THROW(make_step_plan(s, 0, x, std::vector<double>{0.5}, GhostRule::uniform(1)), UsageError);
}

// The owned rows of a run's engine input, ascending id, and the spin's motion from the attached poses.
TEST(StepBodies, OwnedRowsAndTheirMotion) {
  EngineInput in;
  in.position = HostVector<Vec3<double>>{{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}};
  in.radius = HostVector<double>{0.5, 0.6, 0.7, 0.8};
  in.id = HostVector<std::int64_t>{3, 8, 9, 12};
  in.report = HostVector<std::uint8_t>{0, 1, 0, 1};
  in.shapes.shape = HostVector<Shape>{Shape::sphere, Shape::ellipsoid, Shape::sphere, Shape::sphere};
  in.shapes.semi_axes = HostVector<Vec3<double>>(4, Vec3<double>{0.6, 0.3, 0.2});
  in.shapes.orientation = HostVector<Quat<double>>(4, Quat<double>{1, 0, 0, 0});
  in.owned = 2;
  in.ghosts = 2;
  StepBodies b = owned_bodies(in, 2);
  ASSERT_EQ(b.size(), 2u);
  EXPECT_EQ(b.id[0], 8);
  EXPECT_EQ(b.id[1], 12);
  EXPECT_EQ(b.radius[1], 0.8);
  attach_file_poses(b, true, 1);
  StepMotion m;
  Moved moved = move_bodies(b, m, 3, 1);
  EXPECT_FALSE(moved.positions || moved.orientations);  // no spin, no drift: nothing moves
  m.spin = 0.25;
  moved = move_bodies(b, m, 3, 1);
  EXPECT_TRUE(moved.orientations);
  EXPECT_FALSE(moved.positions);
  const Quat<double> q = spun_orientation(8, {1, 0, 0, 0}, 0.75);
  EXPECT_EQ(b.shapes.orientation[0].w, q.w);
  EXPECT_EQ(b.shapes.orientation[0].z, q.z);
  EXPECT_EQ(b.shapes.orientation[1].w, 1.0);          // a sphere keeps its orientation
  EXPECT_TRUE(move_bodies(b, m, 3, 1).orientations);  // from the file pose: the same turn again, not twice
  EXPECT_EQ(b.shapes.orientation[0].x, q.x);
  // the drift: from the file centre, s·V along the body's own unit direction
  m.drift = 0.5;
  EXPECT_TRUE(move_bodies(b, m, 4, 1).positions);
  const Vec3<double> u = drift_direction(12);
  EXPECT_NEAR(std::sqrt(u.x * u.x + u.y * u.y + u.z * u.z), 1.0, 1e-15);
  EXPECT_EQ(b.position[1].x, 3 + u.x * 2.0);
  EXPECT_EQ(b.position[1].y, 0 + u.y * 2.0);
  EXPECT_EQ(b.position[0].z, drifted_position(8, {1, 0, 0}, 0.5, 4).z);
  move_bodies(b, m, 1, 1);
  EXPECT_EQ(b.position[1].x, drifted_position(12, {3, 0, 0}, 0.5, 1).x);  // not accumulated
  const Vec3<double> u8 = drift_direction(8), a8 = spin_axis(8);
  EXPECT_NE(u8.x, a8.x);  // the drift's direction is not the spin's axis
}

// A migration's merge (merge_step_bodies) against sort-by-id of the rows that stay and the arrivals:
// seeded random ids, the changes at both ends, every row leaving, an arrival taking a leaving row's
// id, threads 1 and 4 into spare storage of any size; and the internal errors.
TEST(StepBodies, MigrationMergesByIdInPlaceOfSorting) {
  std::mt19937_64 rng(3101);
  const std::size_t stride = 3;
  auto make = [&](std::vector<std::int64_t> ids, bool shapes) {
    StepBodies b = sized_step_bodies(ids.size(), shapes, stride);
    for (std::size_t k = 0; k < ids.size(); ++k) {
      const double v = double(ids[k]);
      b.id[k] = ids[k];
      b.position[k] = {v, v + 0.25, v + 0.5};
      b.radius[k] = 1 + v / 1024;
      if (shapes) {
        b.shapes.shape[k] = ids[k] % 2 ? Shape::ellipsoid : Shape::sphere;
        b.shapes.semi_axes[k] = {v, 1, 2};
        b.shapes.orientation[k] = {1, v, 0, 0};
      }
      for (std::size_t j = 0; j < stride; ++j) b.state[k * stride + j] = std::byte(ids[k] * 7 + j);
    }
    return b;
  };
  for (int trial = 0; trial < 40; ++trial) {
    const bool shapes = trial % 2 == 1;
    const std::size_t n = trial < 4 ? std::size_t(trial) : std::size_t(rng() % 40000);
    // ids: a random subset of [0, 4n + 8), split into the rows held and the arrivals
    std::vector<std::int64_t> all(4 * n + 8);
    std::iota(all.begin(), all.end(), std::int64_t(0));
    std::shuffle(all.begin(), all.end(), rng);
    const std::size_t m = trial % 5 == 0 ? 0 : std::min(all.size() - n, std::size_t(rng() % 2000));
    std::vector<std::int64_t> held(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(n)),
        come(all.begin() + static_cast<std::ptrdiff_t>(n), all.begin() + static_cast<std::ptrdiff_t>(n + m));
    if (trial == 7 && n > 0) come.push_back(-1);  // an arrival before every row
    std::sort(held.begin(), held.end());
    std::sort(come.begin(), come.end());
    std::vector<std::size_t> leaving;
    const int mode = trial % 4;  // 0: random, 1: none, 2: every row, 3: the first and the last rows
    for (std::size_t k = 0; k < n; ++k)
      if ((mode == 0 && rng() % 50 == 0) || mode == 2 || (mode == 3 && (k == 0 || k + 1 == n)))
        leaving.push_back(k);
    if (trial == 10 && !leaving.empty())
      come.insert(std::upper_bound(come.begin(), come.end(), held[leaving[0]]),
                  held[leaving[0]]);  // back at once
    const StepBodies from = make(held, shapes), arrivals = make(come, shapes);
    std::vector<std::int64_t> want;
    for (std::size_t k = 0, l = 0; k < n; ++k) {
      if (l < leaving.size() && leaving[l] == k) {
        ++l;
        continue;
      }
      want.push_back(held[k]);
    }
    want.insert(want.end(), come.begin(), come.end());
    std::sort(want.begin(), want.end());
    StepBodies into = make(std::vector<std::int64_t>(rng() % 1000, 5), shapes);  // spare of any size
    const std::vector<std::size_t> before =
        merge_step_bodies(from, leaving, arrivals, shapes, into, trial % 3 == 0 ? 1 : 4);
    ASSERT_EQ(into.size(), want.size()) << "trial " << trial;
    // the splice map reads every merged row in place: its source holds the merged row's id
    const SpliceMap map(n, leaving, before);
    ASSERT_EQ(map.size(), want.size());
    for (std::size_t k = 0; k < want.size(); ++k) {
      const SpliceMap::Source src = map(k);
      ASSERT_EQ(src.arrival ? arrivals.id[src.row] : from.id[src.row], want[k])
          << "trial " << trial << " row " << k;
      if (!src.arrival) {
        ASSERT_FALSE(std::binary_search(leaving.begin(), leaving.end(), src.row));
      }
    }
    ASSERT_EQ(into.state.size(), want.size() * stride);
    const StepBodies expect = make(want, shapes);
    for (std::size_t k = 0; k < want.size(); ++k) {
      ASSERT_EQ(into.id[k], want[k]) << "trial " << trial << " row " << k;
      ASSERT_EQ(into.position[k].y, expect.position[k].y);
      ASSERT_EQ(into.radius[k], expect.radius[k]);
      ASSERT_EQ(into.state[k * stride + 2], expect.state[k * stride + 2]);
      if (shapes) {
        ASSERT_EQ(into.shapes.shape[k], expect.shapes.shape[k]);
        ASSERT_EQ(into.shapes.semi_axes[k].x, expect.shapes.semi_axes[k].x);
        ASSERT_EQ(into.shapes.orientation[k].x, expect.shapes.orientation[k].x);
      }
    }
  }
  // a body that arrives while it stays, twice, or leaving rows out of order: internal errors
  const StepBodies from = make({2, 5, 9}, false);
  StepBodies into;
  EXPECT_THROW(merge_step_bodies(from, {}, make({5}, false), false, into, 1), Error);
  EXPECT_THROW(merge_step_bodies(from, {}, make({6, 6}, false), false, into, 1), Error);
  const std::vector<std::size_t> unordered{2, 1};
  EXPECT_THROW(merge_step_bodies(from, unordered, make({}, false), false, into, 1), Error);
  const std::vector<std::size_t> outside{3};
  EXPECT_THROW(merge_step_bodies(from, outside, make({}, false), false, into, 1), Error);
  EXPECT_THROW(merge_step_bodies(from, {}, make({1}, true), false, into, 1), Error);
  // many arrivals, places found in parallel: the first arrival held twice is the one named
  std::vector<std::int64_t> held(3000), come(1000);
  for (std::size_t k = 0; k < held.size(); ++k) held[k] = std::int64_t(2 * k);      // even ids stay
  for (std::size_t j = 0; j < come.size(); ++j) come[j] = std::int64_t(2 * j + 1);  // odd ids arrive
  come[700] = 1400;  // held by a row that stays, as is come[900]
  come[900] = 1800;
  for (const int threads : {1, 4}) {
    try {
      merge_step_bodies(make(held, false), {}, make(come, false), false, into, threads);
      ADD_FAILURE() << "threads " << threads << ": no error";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("body 1400 is held twice"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace cg
