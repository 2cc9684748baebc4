// Unit tests of decomposition/contact_merge.hpp: the k-way merge of the ranks' sorted contact runs.
#include <gtest/gtest.h>

#include <vector>

#include "contact_merge.hpp"

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
    const std::vector<std::int64_t> a = {0, 0, 0, 1, 3, 7, 7}, b = {1, 2, 5, 2, 4, 8, 9};
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
  std::vector<Contacts<double>> runs = {run_of({{0, 1}, {2, 3}}, false), run_of({{0, 1}, {2, 3}, {4, 5}}, false),
                                        run_of({{2, 3}}, false)};
  runs[1].distance[0] = 99.0;  // the copy of rank 1 differs: rank 0's row is kept
  MergedContacts<double> m = merge_contact_runs<double>(runs, false);
  EXPECT_EQ(m.duplicates_removed, 3u);
  EXPECT_EQ(m.contacts.id_a, (std::vector<std::int64_t>{0, 2, 4}));
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

}  // namespace
}  // namespace cg
