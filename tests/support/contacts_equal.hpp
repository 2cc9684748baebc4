#pragma once
// The tests' comparison of contact rows, derived from the one table of contact fields
// (kernels/core/contact_fields.hpp): a new field is compared without touching a test.
#include <cstring>
#include <string>
#include <vector>

#include "contacts.hpp"

namespace cg::test {

// The names of the fields (kContactFields order, every field) whose rows [first, first + got.size())
// of `want` differ from `got` in their bytes, or whose presence differs; "rows" when `got` reaches
// past the end of `want`. Empty: identical.
template <class Real>
std::vector<std::string> differing_fields(const Contacts<Real>& got, const Contacts<Real>& want,
                                          std::size_t first = 0) {
  std::vector<std::string> differ;
  if (first + got.size() > want.size()) differ.push_back("rows");
  zip_contact_fields(got, want, FieldSet::all(), [&](auto index, const auto& g, const auto& w) {
    const ContactField& field = kContactFields[index];
    const bool present = got.fields().has(field.group), w_present = want.fields().has(field.group);
    bool same = present == w_present && (!present || g.size() == got.size());
    if (same && !g.empty())
      same = first + g.size() <= w.size() &&
             std::memcmp(g.data(), w.data() + first, g.size() * sizeof(g[0])) == 0;
    if (!same) differ.push_back(field.name());
  });
  return differ;
}

// "identical" or the differing fields, for a test's failure message.
template <class Real>
std::string compare_contacts(const Contacts<Real>& got, const Contacts<Real>& want, std::size_t first = 0) {
  const std::vector<std::string> d = differing_fields(got, want, first);
  if (d.empty()) return "identical";
  std::string s = "differ in";
  for (const std::string& f : d) s += " " + f;
  return s;
}

}  // namespace cg::test
