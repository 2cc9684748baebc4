#pragma once
// The per-contact fields of docs/FORMAT.md §2, stated once. Every other spelling of the contact schema
// derives from this file: Contacts (host vectors), DeviceContactsView and the CUDA row pointers, the
// narrow stage's row store (both backends), the merge of the ranks' runs, the HDF5 datasets, the CSV
// and the tests' comparers.
//
// A new per-contact field is: one row in kContactFields, one member in ContactColumns (same place),
// one line in zip_contact_fields — then the compiler points at the narrow-phase function that must
// compute it; storage, transfer, merge, files and comparisons follow.
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "core/config.hpp"
#include "core/vec3.hpp"

namespace cg {

enum class FieldKind : std::uint8_t {
  id,      // int64 body id
  vector,  // Vec3<Real>: an (K, 3) dataset
  scalar,  // Real: a (K) dataset
};

struct ContactField {
  const char* path;  // HDF5 dataset of a contact file
  FieldKind kind;
  bool optional;  // present only with Fields::full (docs/FORMAT.md §2: only when the user asked)
  constexpr const char* name() const { return path + 10; }  // path without "/contacts/"
  constexpr int columns() const { return kind == FieldKind::vector ? 3 : 1; }
};

// In the order of the datasets of a contact file, the members of ContactColumns and the CSV columns.
inline constexpr ContactField kContactFields[] = {
    {"/contacts/id_a", FieldKind::id, false},
    {"/contacts/id_b", FieldKind::id, false},
    {"/contacts/position_on_a", FieldKind::vector, false},
    {"/contacts/position_on_b", FieldKind::vector, false},
    {"/contacts/normal_on_b", FieldKind::vector, false},
    {"/contacts/distance", FieldKind::scalar, false},
    {"/contacts/local_point_a", FieldKind::vector, true},
    {"/contacts/local_point_b", FieldKind::vector, true},
    {"/contacts/lateral_friction_dir1", FieldKind::vector, true},
    {"/contacts/lateral_friction_dir2", FieldKind::vector, true},
};
inline constexpr std::size_t kContactFieldCount = sizeof(kContactFields) / sizeof(kContactFields[0]);
// The fields of Fields::basic come first: a run without the optional fields has this many.
inline constexpr std::size_t kBasicContactFieldCount = 6;
static_assert(!kContactFields[kBasicContactFieldCount - 1].optional &&
              kContactFields[kBasicContactFieldCount].optional);

// Column storage of one field of element type T.
template <class T>
using Value = T;  // one row (ContactRow)
template <class T>
using Ptr = T*;  // rows in memory the holder writes (the CUDA row store)
template <class T>
using ConstPtr = const T*;  // rows read in place (device views, the merge's runs)

// One member per row of kContactFields, in its order. Column<T> is the storage: Value (one row), Ptr
// or ConstPtr (arrays elsewhere), HostVector (Contacts).
template <class Real, template <class> class Column>
struct ContactColumns {
  Column<std::int64_t> id_a{}, id_b{};
  Column<Vec3<Real>> position_on_a{}, position_on_b{}, normal_on_b{};
  Column<Real> distance{};
  Column<Vec3<Real>> local_point_a{}, local_point_b{}, lateral_friction_dir1{}, lateral_friction_dir2{};
};

// The index of a field in kContactFields, as a type: device code cannot read kContactFields (a host
// array), host code looks the field up (kContactFields[index]: it converts to std::size_t).
template <std::size_t K>
using FieldIndex = std::integral_constant<std::size_t, K>;

// f(index, column of x, column of y) for every field, in table order; the optional ones only when
// `full`. x and y are ContactColumns of any storage (const or not), so one call copies, compares or
// stores rows between any two of them. Host and device.
template <class X, class Y, class F>
CG_HD void zip_contact_fields(X& x, Y& y, bool full, F&& f) {
  f(FieldIndex<0>{}, x.id_a, y.id_a);
  f(FieldIndex<1>{}, x.id_b, y.id_b);
  f(FieldIndex<2>{}, x.position_on_a, y.position_on_a);
  f(FieldIndex<3>{}, x.position_on_b, y.position_on_b);
  f(FieldIndex<4>{}, x.normal_on_b, y.normal_on_b);
  f(FieldIndex<5>{}, x.distance, y.distance);
  if (full) {
    f(FieldIndex<6>{}, x.local_point_a, y.local_point_a);
    f(FieldIndex<7>{}, x.local_point_b, y.local_point_b);
    f(FieldIndex<8>{}, x.lateral_friction_dir1, y.lateral_friction_dir1);
    f(FieldIndex<9>{}, x.lateral_friction_dir2, y.lateral_friction_dir2);
  }
}

// f(index, column) for every field of one ContactColumns, in table order (optional ones when `full`).
template <class X, class F>
CG_HD void for_each_contact_field(X& x, bool full, F&& f) {
  zip_contact_fields(x, x, full, [&](auto index, auto& column, auto&) { f(index, column); });
}

// One contact row, world frame (the narrow stage computes it; ids are local indices there).
template <class Real>
using ContactRow = ContactColumns<Real, Value>;

// The row store of the narrow stage, shared by both backends: row `row` into rows[k] of every column.
template <class Real, class Columns>
CG_HD void store_row(const Columns& rows, std::size_t k, const ContactRow<Real>& row, bool full) {
  zip_contact_fields(rows, row, full, [k](auto, auto* column, const auto& v) { column[k] = v; });
}

}  // namespace cg
