#pragma once
// The engine's output: contacts in host memory (Contacts) or left in DEVICE memory
// (DeviceContactsView). g++-safe public header (part of engine.hpp).
#include <cstddef>
#include <cstdint>

#include "core/vec3.hpp"
#include "host/huge_pages.hpp"

namespace cg {

// Contacts as CONTRACT §2: sorted by (id_a, id_b), id_a < id_b, world frame.
template <class Real>
struct Contacts {
  // HostVector: a resize leaves new elements uninitialised (no zero sweep of gigabytes before the
  // engine or a receive overwrites them) and large arrays sit on huge pages.
  HostVector<std::int64_t> id_a, id_b;
  HostVector<Vec3<Real>> position_on_a, position_on_b, normal_on_b;
  HostVector<Real> distance;
  bool full = false;  // the four optional datasets below are filled
  HostVector<Vec3<Real>> local_point_a, local_point_b, lateral_friction_dir1, lateral_friction_dir2;

  std::size_t size() const { return id_a.size(); }
  void reserve(std::size_t k,
               bool with_full);  // room for k rows in every field (the optional ones when with_full)
  void resize(std::size_t k, bool with_full);  // k rows, each field allocated exactly once (reserve first)
};

// Contacts left in DEVICE memory, owned by the engine: valid until the engine's next detect call or
// its destruction. Same rows and order as Contacts (sorted by (id_a, id_b)); ids are local indices.
// The four `full` arrays are null unless the engine runs with Fields::full.
template <class Real>
struct DeviceContactsView {
  std::size_t count = 0;
  bool full = false;
  const std::int64_t* id_a = nullptr;
  const std::int64_t* id_b = nullptr;
  const Vec3<Real>* position_on_a = nullptr;
  const Vec3<Real>* position_on_b = nullptr;
  const Vec3<Real>* normal_on_b = nullptr;
  const Real* distance = nullptr;
  const Vec3<Real>* local_point_a = nullptr;
  const Vec3<Real>* local_point_b = nullptr;
  const Vec3<Real>* lateral_friction_dir1 = nullptr;
  const Vec3<Real>* lateral_friction_dir2 = nullptr;
};

}  // namespace cg
