// The slots path of the granular dynamics on the CPU (host/dem_slots.hpp): a rebuild's index and
// remap, the step's forces over the slots, and the contacts made from the slots when asked.
#include "host/dem_slots.hpp"

#include <omp.h>

#include <utility>

#include "host/stages.hpp"

namespace cg::detail::host {

dem::SlotList HostSlots::list() const {
  return {a.data(), b.data(), a.size(), a_begin.data(), b_begin.data(), by_b.data()};
}

void slots_rebuild(HostSlots& s, std::vector<std::uint32_t> a, std::vector<std::uint32_t> b,
                   std::size_t bodies, int threads) {
  const std::size_t m = a.size();
  // the old list's touching slots numbered in slot order: their rows in the last step's contacts
  const std::vector<std::int32_t>& old_age = s.age[s.cur];
  std::vector<std::int64_t> rank(s.a.size());
  std::int64_t row = 0;
  for (std::size_t k = 0; k < s.a.size(); ++k) rank[k] = old_age[k] >= 0 ? row++ : -1;
  std::vector<Vec3<double>> xi(m), normal(m);
  std::vector<std::int32_t> age(m);
  s.prev_row.resize(m);
  const dem::SlotRemap map{
      s.a.data(),  s.b.data(), s.a.size(),    s.xi[s.cur].data(), s.normal[s.cur].data(), old_age.data(),
      rank.data(), xi.data(),  normal.data(), age.data(),         s.prev_row.data()};
  const std::ptrdiff_t mm = static_cast<std::ptrdiff_t>(m);
#pragma omp parallel for num_threads(threads) schedule(static) if (m > k_parallel_min)
  for (std::ptrdiff_t k = 0; k < mm; ++k) dem::remap_slot(std::size_t(k), a.data(), b.data(), m, map);
  s.a = std::move(a);
  s.b = std::move(b);
  s.xi[s.cur] = std::move(xi);
  s.normal[s.cur] = std::move(normal);
  s.age[s.cur] = std::move(age);
  s.xi[1 - s.cur].resize(m);
  s.normal[1 - s.cur].resize(m);
  s.age[1 - s.cur].resize(m);
  s.energy.assign(m, 0);
  s.remapped = true;
  // each body's runs: as A (the list is sorted by a), as B (a stable counting sort by b)
  s.a_begin.assign(bodies + 1, 0);
  s.b_begin.assign(bodies + 1, 0);
  for (std::size_t k = 0; k < m; ++k) {
    ++s.a_begin[s.a[k] + 1];
    ++s.b_begin[s.b[k] + 1];
  }
  for (std::size_t i = 0; i < bodies; ++i) {
    s.a_begin[i + 1] += s.a_begin[i];
    s.b_begin[i + 1] += s.b_begin[i];
  }
  s.by_b.resize(m);
  std::vector<std::uint32_t> at(s.b_begin.begin(), s.b_begin.end() - 1);
  for (std::size_t k = 0; k < m; ++k) s.by_b[at[s.b[k]]++] = std::uint32_t(k);
}

template <class Real>
void slots_forces(HostDem& h, HostSlots& s, const NarrowBodies<Real>& world, const dem::StepConstants& c,
                  int threads) {
  const std::size_t n = h.size();
  h.wall_xi.resize(n * std::size_t(c.wall_count));
  h.wall_energy.resize(n);
  s.force_next.resize(n);
  s.torque_next.resize(n);
  const dem::BodyArrays b = h.arrays();
  const dem::SlotList list = s.list();
  const int now = 1 - s.cur;
  const dem::SlotState st{s.xi[s.cur].data(),   s.normal[s.cur].data(), s.age[s.cur].data(), s.xi[now].data(),
                          s.normal[now].data(), s.age[now].data(),      s.energy.data()};
  const dem::WallTerms w{h.wall_xi.data(), h.wall_energy.data()};
  const std::ptrdiff_t nn = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min / 8)
  for (std::ptrdiff_t i = 0; i < nn; ++i)
    dem::slot_body_terms(std::size_t(i), list, world, b, c, st, w, s.force_next.data(), s.torque_next.data());
  h.force.swap(s.force_next);
  h.torque.swap(s.torque_next);
  s.cur = now;
}

std::size_t slots_contact_count(const std::int32_t* age, std::size_t count) {
  std::size_t k = 0;
  for (std::size_t j = 0; j < count; ++j) k += age[j] >= 0;
  return k;
}

std::size_t slots_contact_count(const HostSlots& s) {
  return slots_contact_count(s.age[s.cur].data(), s.size());
}

void slots_contact_energies(HostDem& h, const HostSlots& s) {
  h.contact_energy.clear();
  const std::vector<std::int32_t>& age = s.age[s.cur];
  for (std::size_t k = 0; k < age.size(); ++k)
    if (age[k] >= 0) h.contact_energy.push_back(s.energy[k]);
}

template <class Real>
Contacts<Real> slots_contacts(const std::uint32_t* a, const std::uint32_t* b, const std::int32_t* age,
                              const std::int32_t* before, const std::int64_t* prev_row, bool remapped,
                              std::size_t count, const NarrowBodies<Real>& world) {
  Contacts<Real> out;
  out.history = true;
  out.resize(slots_contact_count(age, count), FieldSet{false, true});
  std::size_t row = 0;
  std::int64_t prev_rank = 0;  // the slots that touched at the step before, in slot order
  for (std::size_t j = 0; j < count; ++j) {
    const std::int64_t prev = before[j] >= 0 ? prev_rank++ : -1;
    if (age[j] < 0) continue;
    const NarrowDecision<Real> d = dem::slot_decide(world, a[j], b[j]);
    out.id_a[row] = a[j];
    out.id_b[row] = b[j];
    out.position_on_a[row] = d.row.position_on_a;
    out.position_on_b[row] = d.row.position_on_b;
    out.normal_on_b[row] = d.row.normal_on_b;
    out.distance[row] = d.row.distance;
    out.age[row] = age[j];
    // a step that rebuilt the list: the rows the remap found (the old list's numbering)
    out.previous_row[row] = age[j] == 0 ? -1 : (remapped ? prev_row[j] : prev);
    ++row;
  }
  return out;
}

template <class Real>
Contacts<Real> slots_contacts(const HostSlots& s, const NarrowBodies<Real>& world) {
  return slots_contacts(s.a.data(), s.b.data(), s.age[s.cur].data(), s.age[1 - s.cur].data(),
                        s.prev_row.data(), s.remapped, s.size(), world);
}

template void slots_forces(HostDem&, HostSlots&, const NarrowBodies<float>&, const dem::StepConstants&, int);
template void slots_forces(HostDem&, HostSlots&, const NarrowBodies<double>&, const dem::StepConstants&, int);
template Contacts<float> slots_contacts(const HostSlots&, const NarrowBodies<float>&);
template Contacts<float> slots_contacts(const std::uint32_t*, const std::uint32_t*, const std::int32_t*,
                                        const std::int32_t*, const std::int64_t*, bool, std::size_t,
                                        const NarrowBodies<float>&);
template Contacts<double> slots_contacts(const std::uint32_t*, const std::uint32_t*, const std::int32_t*,
                                         const std::int32_t*, const std::int64_t*, bool, std::size_t,
                                         const NarrowBodies<double>&);
template Contacts<double> slots_contacts(const HostSlots&, const NarrowBodies<double>&);

}  // namespace cg::detail::host
