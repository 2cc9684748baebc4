#pragma once
// The engine's output: contacts in host memory (Contacts) or left in DEVICE memory
// (DeviceContactsView). Both are ContactColumns (core/contact_fields.hpp: the one table of the
// per-contact fields), with host vectors or device pointers as the storage.
// g++-safe public header (part of engine.hpp).
#include <cstddef>
#include <cstdint>

#include "core/contact_fields.hpp"
#include "host_vector.hpp"

namespace cg {

// Contacts as docs/FORMAT.md §2: sorted by (id_a, id_b), id_a < id_b, world frame.
// HostVector: a resize leaves new elements uninitialised (no zero sweep of gigabytes before the
// engine or a receive overwrites them) and large arrays sit on huge pages.
template <class Real>
struct Contacts : ContactColumns<Real, HostVector> {
  bool full = false;  // the optional fields (kContactFields[k].optional) are filled

  std::size_t size() const { return this->id_a.size(); }
  // Room for k rows in every field (the optional ones when with_full).
  void reserve(std::size_t k, bool with_full);
  // k rows, each field allocated exactly once (reserve first); the optional fields empty unless with_full.
  void resize(std::size_t k, bool with_full);
  // True when every field present has size() rows (and the optional ones are there when full).
  bool consistent() const;
};

// Contacts left in DEVICE memory, owned by the engine: valid until the engine's next detect call or
// its destruction. Same rows and order as Contacts (sorted by (id_a, id_b)); ids are local indices.
// The optional arrays are null unless the engine runs with Fields::full.
template <class Real>
struct DeviceContactsView : ContactColumns<Real, ConstPtr> {
  std::size_t count = 0;
  bool full = false;
};

// The columns of `c` as pointers (null for an empty field): what the narrow stage's row store
// (store_row) writes through and what the merge reads.
template <class Real>
ContactColumns<Real, Ptr> columns_of(Contacts<Real>& c) {
  ContactColumns<Real, Ptr> p;
  zip_contact_fields(p, c, true,
                     [](auto, auto*& ptr, auto& column) { ptr = column.empty() ? nullptr : column.data(); });
  return p;
}
template <class Real>
ContactColumns<Real, ConstPtr> columns_of(const Contacts<Real>& c) {
  ContactColumns<Real, ConstPtr> p;
  zip_contact_fields(p, c, true, [](auto, auto*& ptr, const auto& column) {
    ptr = column.empty() ? nullptr : column.data();
  });
  return p;
}

}  // namespace cg
