// Unit tests of decomposition/contact_merge.hpp: the k-way merge of the ranks' sorted contact runs.
#include "contact_merge.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <string>
#include <vector>

#include "support/contacts_equal.hpp"

namespace cg {
namespace {

// A run with the given (a, b) rows; every field encodes (a, b) so rows can be traced.
Contacts<double> run_of(std::vector<std::pair<int, int>> rows, bool full) {
  Contacts<double> c;
  c.full = full;
  for (auto [a, b] : rows) {
    c.id_a.push_back(a);
    c.id_b.push_back(b);
    const double v = a * 1000.0 + b;
    c.position_on_a.push_back({v, 1, 0});
    c.position_on_b.push_back({v, 2, 0});
    c.normal_on_b.push_back({v, 3, 0});
    c.distance.push_back(-v);
    if (full) {
      c.local_point_a.push_back({v, 4, 0});
      c.local_point_b.push_back({v, 5, 0});
      c.lateral_friction_dir1.push_back({v, 6, 0});
      c.lateral_friction_dir2.push_back({v, 7, 0});
    }
  }
  return c;
}

TEST(ContactMerge, MergesSortedRunsInKeyOrder) {
  for (bool full : {false, true}) {
    std::vector<Contacts<double>> runs = {run_of({{0, 1}, {0, 5}, {7, 9}}, full), run_of({}, full),
                                          run_of({{0, 2}, {3, 4}, {7, 8}}, full), run_of({{1, 2}}, full)};
    MergedContacts<double> m = merge_contact_runs<double>(runs, full);
    EXPECT_EQ(m.duplicates_removed, 0u);
    ASSERT_EQ(m.contacts.size(), 7u);
    EXPECT_EQ(m.contacts.full, full);
    const HostVector<std::int64_t> a = {0, 0, 0, 1, 3, 7, 7}, b = {1, 2, 5, 2, 4, 8, 9};
    EXPECT_EQ(m.contacts.id_a, a);
    EXPECT_EQ(m.contacts.id_b, b);
    for (std::size_t k = 0; k < a.size(); ++k) {
      const double v = a[k] * 1000.0 + b[k];
      EXPECT_EQ(m.contacts.position_on_a[k].x, v);
      EXPECT_EQ(m.contacts.position_on_b[k].y, 2.0);
      EXPECT_EQ(m.contacts.distance[k], -v);
      if (full) {
        EXPECT_EQ(m.contacts.lateral_friction_dir2[k].y, 7.0);
      }
    }
    EXPECT_EQ(m.contacts.local_point_a.size(), full ? 7u : 0u);
  }
}

TEST(ContactMerge, RemovesAndCountsDuplicatesKeepingTheLowestRunsRow) {
  std::vector<Contacts<double>> runs = {run_of({{0, 1}, {2, 3}}, false),
                                        run_of({{0, 1}, {2, 3}, {4, 5}}, false), run_of({{2, 3}}, false)};
  runs[1].distance[0] = 99.0;  // the copy of rank 1 differs: rank 0's row is kept
  MergedContacts<double> m = merge_contact_runs<double>(runs, false);
  EXPECT_EQ(m.duplicates_removed, 3u);
  EXPECT_EQ(m.contacts.id_a, (HostVector<std::int64_t>{0, 2, 4}));
  EXPECT_EQ(m.contacts.distance[0], -1.0);
}

TEST(ContactMerge, NoRunsOrEmptyRuns) {
  std::vector<Contacts<double>> none;
  EXPECT_EQ(merge_contact_runs<double>(none, false).contacts.size(), 0u);
  std::vector<Contacts<double>> empty(3);
  EXPECT_EQ(merge_contact_runs<double>(empty, false).contacts.size(), 0u);
}

TEST(ContactMerge, RejectsUnsortedOrRaggedRuns) {
  std::vector<Contacts<double>> unsorted = {run_of({{2, 3}, {0, 1}}, false)};
  EXPECT_THROW(merge_contact_runs<double>(unsorted, false), Error);
  std::vector<Contacts<double>> ragged = {run_of({{0, 1}}, false)};
  ragged[0].distance.clear();
  EXPECT_THROW(merge_contact_runs<double>(ragged, false), Error);
  std::vector<Contacts<double>> not_full = {run_of({{0, 1}}, false)};
  EXPECT_THROW(merge_contact_runs<double>(not_full, true), Error);
}

// The parallel form (views in, presized result) gives merge_contact_runs's rows and duplicate count
// for any number of parts and threads, duplicates across runs and parts included.
TEST(ContactMerge, IntoEqualsTheSequentialMergeForAnyParts) {
  std::mt19937 rng(7);
  for (bool full : {false, true}) {
    for (int trial = 0; trial < 20; ++trial) {
      const int p = trial % 4 == 3 ? 9 + trial % 7 : 1 + trial % 5;  // up to 8: linear scan; more: heap
      std::vector<Contacts<double>> runs;
      for (int r = 0; r < p; ++r) {
        std::vector<std::pair<int, int>> rows;
        const int n = static_cast<int>(rng() % 200);
        for (int k = 0; k < n; ++k) {
          const int a = static_cast<int>(rng() % 40);
          rows.emplace_back(a, a + 1 + static_cast<int>(rng() % 5));  // few keys: many duplicates
        }
        std::sort(rows.begin(), rows.end());
        runs.push_back(run_of(rows, full));
        for (std::size_t k = 0; k < runs.back().size(); ++k) runs.back().distance[k] += r;  // traces the run
      }
      const MergedContacts<double> want = merge_contact_runs<double>(runs, full);
      std::vector<ContactRunView<double>> views;
      std::size_t total = 0;
      for (Contacts<double>& c : runs) {
        views.push_back(contact_run_view(c, full));
        total += c.size();
      }
      for (int parts : {1, 2, 3, 8, 64}) {
        for (int threads : {1, 3}) {
          Contacts<double> got;
          got.resize(total, full);
          const std::uint64_t dups = merge_contact_runs_into<double>(views, got, full, parts, threads);
          EXPECT_EQ(dups, want.duplicates_removed) << parts;
          ASSERT_EQ(got.size(), want.contacts.size()) << parts;
          EXPECT_EQ(test::compare_contacts(got, want.contacts), "identical") << parts;
        }
      }
    }
  }
}

TEST(ContactMerge, IntoRejectsUnsortedRunsAndAWronglySizedResult) {
  std::vector<Contacts<double>> runs = {run_of({{0, 1}}, false), run_of({{2, 3}, {0, 1}}, false)};
  std::vector<ContactRunView<double>> views = {contact_run_view(runs[0], false),
                                               contact_run_view(runs[1], false)};
  Contacts<double> out;
  out.resize(3, false);
  try {
    merge_contact_runs_into<double>(views, out, false, 2, 1);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("contact run 1: not sorted by (id_a, id_b) at row 1"),
              std::string::npos)
        << e.what();
  }
  runs[1] = run_of({{0, 1}, {2, 3}}, false);
  views[1] = contact_run_view(runs[1], false);
  out.resize(2, false);
  EXPECT_THROW(merge_contact_runs_into<double>(views, out, false, 2, 1), Error);
}

}  // namespace
}  // namespace cg
