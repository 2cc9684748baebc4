#pragma once
// The per-contact fields of docs/FORMAT.md §2, stated once. Every other spelling of the contact schema
// derives from this file: Contacts (host vectors), DeviceContactsView and the CUDA row pointers, the
// narrow stage's row store (both backends), the merge of the ranks' runs, the HDF5 datasets, the CSV
// and the tests' comparers.
//
// A new per-contact field is: one row in kContactFields, one member in ContactColumns (same place),
// one line in zip_contact_fields — then the compiler points at the narrow-phase function that must
// compute it; storage, transfer, merge, files and comparisons follow.
//
// The fields come in groups (FieldGroup): the basic ones always; `full` (local points, friction
// directions: the narrow stage computes them) and `history` (age, previous_row: the engine's history
// stage computes them, core/history.hpp) only on request. A FieldSet says which optional groups a set
// of rows carries.
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "core/config.hpp"
#include "core/vec3.hpp"

namespace cg {

enum class FieldKind : std::uint8_t {
  integer,  // int64: a body id, a count of steps or a row
  vector,   // Vec3<Real>: an (K, 3) dataset
  scalar,   // Real: a (K) dataset
};

// Which rows a field belongs to: basic (always), full (EngineOptions::fields == Fields::full) or
// history (EngineOptions::history). docs/FORMAT.md §2: the optional ones exist only when the user asked.
enum class FieldGroup : std::uint8_t { basic, full, history };

struct ContactField {
  const char* path;  // HDF5 dataset of a contact file
  FieldKind kind;
  FieldGroup group;
  constexpr bool optional() const { return group != FieldGroup::basic; }
  constexpr const char* name() const { return path + 10; }  // path without "/contacts/"
  constexpr int columns() const { return kind == FieldKind::vector ? 3 : 1; }
};

// The optional groups a set of rows carries (the basic fields always). Made from a bool it is the
// rows the narrow stage computes, with or without the full fields and without history: what the row
// store writes, and what a merge of several engines' runs carries (previous_row is one engine's row
// number, so merged rows take their history anew, core/history.hpp).
struct FieldSet {
  bool full = false;
  bool history = false;
  constexpr FieldSet() = default;
  constexpr FieldSet(bool full_) : full(full_) {}  // NOLINT(google-explicit-constructor): see above
  constexpr FieldSet(bool full_, bool history_) : full(full_), history(history_) {}
  static constexpr FieldSet all() { return {true, true}; }
  constexpr bool has(FieldGroup g) const {
    return g == FieldGroup::basic || (g == FieldGroup::full && full) || (g == FieldGroup::history && history);
  }
  constexpr bool operator==(const FieldSet&) const = default;
};

// In the order of the datasets of a contact file, the members of ContactColumns and the CSV columns.
inline constexpr ContactField kContactFields[] = {
    {"/contacts/id_a", FieldKind::integer, FieldGroup::basic},
    {"/contacts/id_b", FieldKind::integer, FieldGroup::basic},
    {"/contacts/position_on_a", FieldKind::vector, FieldGroup::basic},
    {"/contacts/position_on_b", FieldKind::vector, FieldGroup::basic},
    {"/contacts/normal_on_b", FieldKind::vector, FieldGroup::basic},
    {"/contacts/distance", FieldKind::scalar, FieldGroup::basic},
    {"/contacts/local_point_a", FieldKind::vector, FieldGroup::full},
    {"/contacts/local_point_b", FieldKind::vector, FieldGroup::full},
    {"/contacts/lateral_friction_dir1", FieldKind::vector, FieldGroup::full},
    {"/contacts/lateral_friction_dir2", FieldKind::vector, FieldGroup::full},
    {"/contacts/age", FieldKind::integer, FieldGroup::history},
    {"/contacts/previous_row", FieldKind::integer, FieldGroup::history},
};
inline constexpr std::size_t kContactFieldCount = sizeof(kContactFields) / sizeof(kContactFields[0]);
// The fields of Fields::basic come first: a run without the optional fields has this many.
inline constexpr std::size_t kBasicContactFieldCount = 6;
static_assert(!kContactFields[kBasicContactFieldCount - 1].optional() &&
              kContactFields[kBasicContactFieldCount].optional());

// The number of fields a set of rows carries (the datasets of its contact file).
constexpr std::size_t field_count(FieldSet set) {
  std::size_t n = 0;
  for (const ContactField& f : kContactFields) n += set.has(f.group) ? 1 : 0;
  return n;
}

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
  // history: steps the pair has touched without a break (0 on its first), its row in the previous
  // step's contacts (-1: new). Bullet's lifeTime; what a force model carries tangential history by.
  Column<std::int64_t> age{}, previous_row{};
};

// The index of a field in kContactFields, as a type: device code cannot read kContactFields (a host
// array), host code looks the field up (kContactFields[index]: it converts to std::size_t).
template <std::size_t K>
using FieldIndex = std::integral_constant<std::size_t, K>;

// f(index, column of x, column of y) for every field, in table order; the optional ones only when
// `set` has their group. x and y are ContactColumns of any storage (const or not), so one call
// copies, compares or stores rows between any two of them. Host and device.
template <class X, class Y, class F>
CG_HD void zip_contact_fields(X& x, Y& y, FieldSet set, F&& f) {
  f(FieldIndex<0>{}, x.id_a, y.id_a);
  f(FieldIndex<1>{}, x.id_b, y.id_b);
  f(FieldIndex<2>{}, x.position_on_a, y.position_on_a);
  f(FieldIndex<3>{}, x.position_on_b, y.position_on_b);
  f(FieldIndex<4>{}, x.normal_on_b, y.normal_on_b);
  f(FieldIndex<5>{}, x.distance, y.distance);
  if (set.full) {
    f(FieldIndex<6>{}, x.local_point_a, y.local_point_a);
    f(FieldIndex<7>{}, x.local_point_b, y.local_point_b);
    f(FieldIndex<8>{}, x.lateral_friction_dir1, y.lateral_friction_dir1);
    f(FieldIndex<9>{}, x.lateral_friction_dir2, y.lateral_friction_dir2);
  }
  if (set.history) {
    f(FieldIndex<10>{}, x.age, y.age);
    f(FieldIndex<11>{}, x.previous_row, y.previous_row);
  }
}

// f(index, column) for every field of one ContactColumns, in table order (optional ones in `set`).
template <class X, class F>
CG_HD void for_each_contact_field(X& x, FieldSet set, F&& f) {
  zip_contact_fields(x, x, set, [&](auto index, auto& column, auto&) { f(index, column); });
}

// One contact row, world frame (the narrow stage computes it; ids are local indices there).
template <class Real>
using ContactRow = ContactColumns<Real, Value>;

// The row store of the narrow stage, shared by both backends: row `row` into rows[k] of every column
// it computes (the history stage fills the history columns later).
template <class Real, class Columns>
CG_HD void store_row(const Columns& rows, std::size_t k, const ContactRow<Real>& row, bool full) {
  zip_contact_fields(rows, row, full, [k](auto, auto* column, const auto& v) { column[k] = v; });
}

}  // namespace cg
