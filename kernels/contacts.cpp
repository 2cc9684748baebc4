// Contacts: allocation of the result vectors, field by field from the one table.
#include "contacts.hpp"

namespace cg {

template <class Real>
void Contacts<Real>::reserve(std::size_t k, FieldSet set) {
  for_each_contact_field(*this, set, [k](auto, auto& column) { column.reserve(k); });
}

template <class Real>
void Contacts<Real>::resize(std::size_t k, FieldSet set) {
  reserve(k, set);  // exact: growing by resize alone may over-allocate a non-empty vector
  full = set.full;
  history = set.history;
  for_each_contact_field(*this, FieldSet::all(), [&](auto index, auto& column) {
    column.resize(set.has(kContactFields[index].group) ? k : 0);
  });
}

template <class Real>
bool Contacts<Real>::consistent() const {
  bool ok = true;
  for_each_contact_field(*this, fields(),
                         [&](auto, const auto& column) { ok = ok && column.size() == size(); });
  return ok;
}

template struct Contacts<float>;
template struct Contacts<double>;

}  // namespace cg
