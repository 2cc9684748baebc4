#pragma once
// The CPU backend of the granular dynamics' slots path (core/dem_slots.hpp; the sequence is
// kernels/dem_slots.cpp): the kept candidate list with each body's index, the slots' state in two
// buffers, and the stages over them, OpenMP loops over the per-item functions of core/dem_slots.hpp —
// the CUDA backend's oracle bit for bit.
#include <cstdint>
#include <vector>

#include "core/dem_slots.hpp"
#include "dem.hpp"
#include "host/dem_stages.hpp"

namespace cg::detail::host {

struct HostSlots {
  // the list: pairs (a < b) sorted by (a, b), each body's runs (SlotList)
  std::vector<std::uint32_t> a, b, a_begin, b_begin, by_b;
  // the state: [cur] the last step's, [1 - cur] this step's; energy and age of the last step
  std::vector<Vec3<double>> xi[2], normal[2];
  std::vector<std::int32_t> age[2];
  std::vector<double> energy;
  int cur = 0;
  // the contacts' previous_row at the step of a rebuild (remap_slot); valid while `remapped`
  std::vector<std::int64_t> prev_row;
  bool remapped = false;
  // the forces of the step, written beside the last step's (swapped after)
  std::vector<Vec3<double>> force_next, torque_next;

  std::size_t size() const { return a.size(); }
  dem::SlotList list() const;
};

// A new list (pairs a < b sorted by (a, b)) for `bodies` bodies: its index, and the state of each
// pair carried from the old list (remap_slot); the old list is dropped.
void slots_rebuild(HostSlots& s, std::vector<std::uint32_t> a, std::vector<std::uint32_t> b,
                   std::size_t bodies, int threads);

// The forces of a step over the slots (slot_body_terms of every body; `world`: the step's narrow
// bodies), then this step's state is the last step's (cur flips) and the forces are swapped in.
template <class Real>
void slots_forces(HostDem& h, HostSlots& s, const NarrowBodies<Real>& world, const dem::StepConstants& c,
                  int threads);

// The contacts of the last step (touching slots in slot order): their number, their energies in
// h.contact_energy (the rows path's array: dem_energies sums it), their rows with history.
std::size_t slots_contact_count(const HostSlots& s);
std::size_t slots_contact_count(const std::int32_t* age, std::size_t count);
void slots_contact_energies(HostDem& h, const HostSlots& s);
template <class Real>
Contacts<Real> slots_contacts(const HostSlots& s, const NarrowBodies<Real>& world);
// The same from the arrays of a list of `count` slots (host copies of the CUDA backend's): pairs,
// ages of the last step and of the step before, previous rows of a rebuild's step (`remapped`).
template <class Real>
Contacts<Real> slots_contacts(const std::uint32_t* a, const std::uint32_t* b, const std::int32_t* age,
                              const std::int32_t* before, const std::int64_t* prev_row, bool remapped,
                              std::size_t count, const NarrowBodies<Real>& world);

}  // namespace cg::detail::host
