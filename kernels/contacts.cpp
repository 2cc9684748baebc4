// Contacts: allocation of the result vectors, field by field from the one table.
#include "contacts.hpp"

namespace cg {

template <class Real>
void Contacts<Real>::reserve(std::size_t k, bool with_full) {
  for_each_contact_field(*this, with_full, [k](auto, auto& column) { column.reserve(k); });
}

template <class Real>
void Contacts<Real>::resize(std::size_t k, bool with_full) {
  reserve(k, with_full);  // exact: growing by resize alone may over-allocate a non-empty vector
  full = with_full;
  for_each_contact_field(*this, true, [&](auto index, auto& column) {
    const ContactField& f = kContactFields[index];
    column.resize(f.optional && !with_full ? 0 : k);
  });
}

template <class Real>
bool Contacts<Real>::consistent() const {
  bool ok = true;
  for_each_contact_field(*this, full, [&](auto, const auto& column) { ok = ok && column.size() == size(); });
  return ok;
}

template struct Contacts<float>;
template struct Contacts<double>;

}  // namespace cg
