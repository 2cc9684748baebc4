// The tests' contact comparer (tests/support/contacts_equal.hpp) names every field of the contact-field
// table that differs: one flipped bit in any field, any row, is found and named; rows of a wider real
// type compare once rounded.
#include "support/contacts_equal.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

namespace cg::test {
namespace {

// k rows with distinct values in every field of `set` (the optional groups: full, history).
template <class Real>
Contacts<Real> rows(std::size_t k, FieldSet set) {
  Contacts<Real> c;
  c.resize(k, set);
  for_each_contact_field(c, set, [&](auto index, auto& column) {
    for (std::size_t i = 0; i < k; ++i) {
      const double v = 0.1 * double(index) + 1.7 * double(i) + 1;
      using T = std::decay_t<decltype(column[i])>;
      if constexpr (std::is_arithmetic_v<T>)
        column[i] = static_cast<T>(v);
      else
        column[i] = {static_cast<decltype(T{}.x)>(v), static_cast<decltype(T{}.x)>(-v),
                     static_cast<decltype(T{}.x)>(2 * v)};
    }
  });
  return c;
}

// Flips the lowest bit of row `row`'s first byte in field `field` of c.
template <class Real>
void flip(Contacts<Real>& c, std::size_t field, std::size_t row) {
  for_each_contact_field(c, FieldSet::all(), [&](auto index, auto& column) {
    if (index != field) return;
    unsigned char byte;
    std::memcpy(&byte, &column[row], 1);
    byte ^= 1u;
    std::memcpy(&column[row], &byte, 1);
  });
}

TEST(ContactsEqual, NamesEveryFieldOfTheTable) {
  const Contacts<double> want = rows<double>(5, FieldSet::all());
  EXPECT_EQ(compare_contacts(want, want), "identical");
  for (std::size_t f = 0; f < kContactFieldCount; ++f) {
    for (std::size_t row : {0u, 4u}) {
      Contacts<double> got = want;
      flip(got, f, row);
      EXPECT_EQ(differing_fields(got, want), std::vector<std::string>{kContactFields[f].name()})
          << kContactFields[f].name() << " row " << row;
      EXPECT_EQ(differing_fields_at(got, row, want, row), std::vector<std::string>{kContactFields[f].name()})
          << kContactFields[f].name() << " row " << row;
      EXPECT_EQ(compare_rows(got, row == 0 ? 4 : 0, want, row == 0 ? 4 : 0), "identical");
    }
  }
}

TEST(ContactsEqual, PresenceAndRowRanges) {
  const Contacts<float> full = rows<float>(6, FieldSet::all()), basic = rows<float>(6, false);
  EXPECT_EQ(compare_contacts(basic, basic), "identical");
  const std::vector<std::string> optional = differing_fields(basic, full);
  EXPECT_EQ(optional.size(), kContactFieldCount - kBasicContactFieldCount);
  EXPECT_EQ(compare_rows(basic, 0, full, 0), "differ in full history");
  Contacts<float> tail = rows<float>(6, FieldSet::all());
  EXPECT_EQ(compare_contact_window(tail, full, 0), "identical");
  EXPECT_NE(compare_contact_window(tail, full, 1), "identical");  // rows 1 … 6 of a 6-row set: past the end
  // whole sets: a set that lost its last rows is not identical, either way round
  const Contacts<float> five = rows<float>(5, FieldSet::all());
  EXPECT_EQ(compare_contact_window(five, full, 0), "identical");
  EXPECT_EQ(compare_contacts(five, full), "differ in rows");  // (the five rows are the six's first)
  EXPECT_EQ(compare_contacts(full, five).substr(0, 14), "differ in rows");
  EXPECT_EQ(compare_contacts(Contacts<float>{}, full).substr(0, 14), "differ in rows");
}

TEST(ContactsEqual, WiderRowsCompareRounded) {
  const Contacts<double> wide = rows<double>(4, FieldSet::all());
  Contacts<float> narrow = rows<float>(4, FieldSet::all());  // the same values rounded to float
  EXPECT_EQ(compare_contacts(narrow, wide), "identical");
  EXPECT_EQ(compare_rows(narrow, 3, wide, 3), "identical");
  narrow.distance[2] = std::nextafter(narrow.distance[2], 1e9f);
  EXPECT_EQ(compare_contacts(narrow, wide), "differ in distance");
  EXPECT_EQ(compare_rows(narrow, 2, wide, 2), "differ in distance");
}

}  // namespace
}  // namespace cg::test
