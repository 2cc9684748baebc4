#pragma once
// The tests' comparison of contact rows, derived from the one table of contact fields
// (kernels/core/contact_fields.hpp): a new field is compared without touching a test. Rows compare
// by their bits; rows of a wider real type (fp64's against fp32's, a file read back in double) are
// rounded to the narrower type first, so "identical" means "the same bits once rounded".
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "contacts.hpp"

namespace cg::test {

// `w` rounded to the element type T of a contact column (ids, reals, Vec3 of reals).
template <class T, class U>
T rounded_to(const U& w) {
  if constexpr (std::is_same_v<T, U>)
    return w;
  else if constexpr (std::is_arithmetic_v<T>)
    return static_cast<T>(w);
  else
    return vec_cast<decltype(T{}.x)>(w);
}

// Row i of column g and row j of column w, w rounded to g's element type, have the same bits.
template <class G, class W>
bool same_row(const G& g, std::size_t i, const W& w, std::size_t j) {
  using T = std::decay_t<decltype(g[i])>;
  const T r = rounded_to<T>(w[j]);
  return std::memcmp(&g[i], &r, sizeof(T)) == 0;
}

// The names of the fields (kContactFields order, every field) whose rows [first, first + got.size())
// of `want` differ from `got` in their bits (want rounded to got's real type), or whose presence
// differs; "rows" when `got` reaches past the end of `want`. Empty: identical.
template <class Real, class Wide = Real>
std::vector<std::string> differing_fields(const Contacts<Real>& got, const Contacts<Wide>& want,
                                          std::size_t first = 0) {
  std::vector<std::string> differ;
  if (first + got.size() > want.size()) differ.push_back("rows");
  zip_contact_fields(got, want, FieldSet::all(), [&](auto index, const auto& g, const auto& w) {
    const ContactField& field = kContactFields[index];
    const bool present = got.fields().has(field.group), w_present = want.fields().has(field.group);
    bool same = present == w_present && (!present || g.size() == got.size());
    if (same && !g.empty()) {
      same = first + g.size() <= w.size();
      if constexpr (std::is_same_v<Real, Wide>) {
        same = same && std::memcmp(g.data(), w.data() + first, g.size() * sizeof(g[0])) == 0;
      } else {
        for (std::size_t i = 0; same && i < g.size(); ++i) same = same_row(g, i, w, first + i);
      }
    }
    if (!same) differ.push_back(field.name());
  });
  return differ;
}

// The names of the fields whose row k of `got` differs from row m of `want` (want rounded to got's
// real type); "full" ("history") when one has that optional group and the other not. Empty: identical.
template <class Real, class Wide = Real>
std::vector<std::string> differing_fields_at(const Contacts<Real>& got, std::size_t k,
                                             const Contacts<Wide>& want, std::size_t m) {
  std::vector<std::string> differ;
  if (got.full != want.full) differ.push_back("full");
  if (got.history != want.history) differ.push_back("history");
  const FieldSet both{got.full && want.full, got.history && want.history};
  zip_contact_fields(got, want, both, [&](auto index, const auto& g, const auto& w) {
    if (k >= g.size() || m >= w.size() || !same_row(g, k, w, m))
      differ.push_back(kContactFields[index].name());
  });
  return differ;
}

// "identical" or "differ in <fields>", for a test's failure message.
inline std::string describe_difference(const std::vector<std::string>& fields) {
  if (fields.empty()) return "identical";
  std::string s = "differ in";
  for (const std::string& f : fields) s += " " + f;
  return s;
}

// "identical" or how two whole sets differ: "rows" when their row counts differ (a set that lost its
// last rows is not a prefix match), and the differing fields of the rows they share.
template <class Real, class Wide = Real>
std::string compare_contacts(const Contacts<Real>& got, const Contacts<Wide>& want) {
  std::vector<std::string> differ = differing_fields(got, want, 0);
  if (got.size() < want.size()) differ.insert(differ.begin(), "rows");
  return describe_difference(differ);
}

// "identical" or the differing fields of the rows [first, first + got.size()) of `want` (a window of
// it: a piece of a whole set).
template <class Real, class Wide = Real>
std::string compare_contact_window(const Contacts<Real>& got, const Contacts<Wide>& want, std::size_t first) {
  return describe_difference(differing_fields(got, want, first));
}

// "identical" or the differing fields of row k of `got` and row m of `want`.
template <class Real, class Wide = Real>
std::string compare_rows(const Contacts<Real>& got, std::size_t k, const Contacts<Wide>& want,
                         std::size_t m) {
  return describe_difference(differing_fields_at(got, k, want, m));
}

}  // namespace cg::test
