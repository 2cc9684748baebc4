#pragma once
// The granular dynamics' force stage over the kept candidate list (the slots path; the rows path is
// core/dem_step.hpp), shared by both backends, as LAMMPS' fix neigh/history and DEM-Engine carry a
// contact's history: in the neighbour list's own slots, not in rows of contacts.
//
//   slots         the candidate pairs (a < b, local rows, sorted by (a, b)) of a Verlet skin: every
//                 pair within r_a + r_b + skin at the list's build, so every contact while the bodies
//                 moved less than skin/2 since (core/skin.hpp's rule). The contacts of a step are the
//                 slots whose pair touches, in slot order: the engine's contact rows, in their order.
//   slot state    per slot, what a contact carries across steps: the spring xi, the normal of the
//                 last step (the half-step normal's), the age (-1: not touching at that step), and
//                 the contact's energy (0 when not touching). Two buffers: the last step's (read) and
//                 this step's (written by the pair's A side alone), so any thread order gives the
//                 same bits. A pair that stops touching resets (age -1): a pair absent from the last
//                 step's contacts is new, as the rows path's history says.
//   slot_body_terms(i)  body i's force and torque: its slots as A (slot order: ascending b), then
//                 its slots as B (ascending a, by_b), each pair tested with the engine's narrow-phase
//                 function in the engine's precision (narrow_decide: the engine's point, normal and
//                 distance, bit for bit), its Hertz–Mindlin terms computed in the pair's canonical
//                 orientation (contact_result: both sides the same bits, Newton's third law exact),
//                 summed in registers — the rows path's sums in the rows path's order, so the same
//                 bits — then the walls and gravity (body_terms_after_contacts). Nothing per contact
//                 is stored but the slot state.
//   remap_slot(s) at a rebuild: slot s of the new list takes the state of its pair's slot in the old
//                 list (one search of the old keys from the slot's own place), or a fresh one.
//   slot_row(s)   a touching slot's contact row, when a caller asks for rows (the same bits as the
//                 engine's: the same narrow function on the same positions).
// The positions a step's forces read are those its kick_drift left; the kick after changes
// velocities only, so the rows recomputed after a step are the step's.
#include <cstddef>
#include <cstdint>

#include "core/dem_step.hpp"
#include "core/history.hpp"
#include "core/narrow.hpp"

namespace cg::dem {

// The kept candidate list (host or DEVICE) and where each body's slots lie: as A the run
// [a_begin[i], a_begin[i + 1]) (slots sorted by (a, b)), as B by_b[j] for j in
// [b_begin[i], b_begin[i + 1]) (the slots stably ordered by b: ascending a within a body).
struct SlotList {
  const std::uint32_t* a;
  const std::uint32_t* b;
  std::size_t count;
  const std::uint32_t* a_begin;  // bodies + 1
  const std::uint32_t* b_begin;  // bodies + 1
  const std::uint32_t* by_b;     // count
};

// The slots' state: the last step's (old_*, read) and this step's (written by the slot's A side).
struct SlotState {
  const Vec3<double>* old_xi;
  const Vec3<double>* old_normal;
  const std::int32_t* old_age;  // -1: the pair did not touch at the last step
  Vec3<double>* xi;
  Vec3<double>* normal;
  std::int32_t* age;
  double* energy;
};

// The positions the narrow phase reads: the engine's NarrowBodies of this step (world doubles, the
// frame's origin; fp32: each sphere packed on the fly as the engine's pack packs it,
// Real(world − origin), Real(r): the same floats).
template <class Real>
CG_HD Sphere<Real> slot_sphere(const NarrowBodies<Real>& w, std::uint32_t i) {
  const std::size_t i3 = 3 * std::size_t(i);
  return {static_cast<Real>(w.position[i3] - w.origin.x), static_cast<Real>(w.position[i3 + 1] - w.origin.y),
          static_cast<Real>(w.position[i3 + 2] - w.origin.z), static_cast<Real>(w.radius[i])};
}

// The engine's decision and row of pair (a, b), a < b (core/narrow.hpp: narrow_decide), basic fields.
template <class Real>
CG_HD NarrowDecision<Real> slot_decide(const NarrowBodies<Real>& w, std::uint32_t a, std::uint32_t b) {
  NarrowFlags flags;
  if constexpr (std::is_same_v<Real, double>)
    return narrow_decide(w, a, b, false, flags);
  else
    return narrow_decide_floats(w, slot_sphere(w, a), slot_sphere(w, b), a, b, false, flags);
}

// A touching slot's terms (contact_result of a one-row ContactRows: the rows path's arithmetic on the
// same values). old: the slot's last-step state when the pair touched then (else new).
template <class Real>
CG_HD ContactResult slot_result(std::size_t s, std::uint32_t a, std::uint32_t b, const ContactRow<Real>& row,
                                const BodyArrays& bodies, const StepConstants& c, const SlotState& st) {
  const std::int64_t ia = a, ib = b;
  const std::int64_t prev = st.old_age[s] >= 0 ? std::int64_t(s) : -1;
  const ContactRows<Real> one{
      &ia, &ib, &row.position_on_a, &row.position_on_b, &row.normal_on_b, &row.distance, &prev, 1};
  return contact_result(0, one, bodies, c, st.old_xi, st.old_normal);
}

// Slot s's new state from its result (touching) or reset (not touching): the A side's write.
CG_HD void store_slot(std::size_t s, bool touching, const ContactResult& r, const SlotState& st) {
  if (!touching) {
    st.age[s] = -1;
    st.energy[s] = 0;
    return;
  }
  const std::int32_t old = st.old_age[s];
  st.xi[s] = r.xi;
  st.normal[s] = r.normal;
  st.age[s] = old >= 0 ? old + 1 : 0;
  st.energy[s] = r.energy;
}

// Body i's force and torque of the step (file comment) into force_out[i], torque_out[i]; `bodies`
// holds the last step's forces (the synchronised velocities read them). The walls' springs and
// energies into w.
template <class Real>
CG_HD void slot_body_terms(std::size_t i, const SlotList& list, const NarrowBodies<Real>& world,
                           const BodyArrays& bodies, const StepConstants& c, const SlotState& st,
                           const WallTerms& w, Vec3<double>* force_out, Vec3<double>* torque_out) {
  Vec3<double> f{0, 0, 0}, tau{0, 0, 0};
  const std::uint32_t me = static_cast<std::uint32_t>(i);
  for (std::uint32_t s = list.a_begin[i]; s < list.a_begin[i + 1]; ++s) {
    const std::uint32_t other = list.b[s];
    const NarrowDecision<Real> d = slot_decide(world, me, other);
    ContactResult r{};
    if (d.contact) {
      r = slot_result(s, me, other, d.row, bodies, c, st);
      f = f + r.force;
      tau = tau + r.torque_a;
    }
    store_slot(s, d.contact, r, st);
  }
  for (std::uint32_t j = list.b_begin[i]; j < list.b_begin[i + 1]; ++j) {
    const std::uint32_t s = list.by_b[j];
    const std::uint32_t other = list.a[s];
    const NarrowDecision<Real> d = slot_decide(world, other, me);
    if (!d.contact) continue;
    const ContactResult r = slot_result(s, other, me, d.row, bodies, c, st);
    f = f - r.force;
    tau = tau + r.torque_b;
  }
  body_terms_after_contacts(i, bodies, c, w, f, tau, force_out, torque_out);
}

// The keys of a list's slots (local rows; a single rank's rows are their own ids).
CG_HD PairKey slot_key(const std::uint32_t* a, const std::uint32_t* b, std::size_t s) {
  return PairKey{std::int64_t(a[s]), std::int64_t(b[s])};
}

// A rebuild: slot s of the new list (na, nb) takes its pair's state in the old list (oa, ob, old
// count m; the state of its last step: xi, normal, age) into the new list's last-step buffers, or a
// fresh state (age -1). rank: each old slot's row among the old list's touching slots (an exclusive
// scan of age >= 0), written into prev_row[s] (-1 when the pair did not touch): the contact's
// previous_row at the step of the rebuild.
struct SlotRemap {
  const std::uint32_t* old_a;
  const std::uint32_t* old_b;
  std::size_t old_count;
  const Vec3<double>* old_xi;
  const Vec3<double>* old_normal;
  const std::int32_t* old_age;
  const std::int64_t* old_rank;
  Vec3<double>* xi;
  Vec3<double>* normal;
  std::int32_t* age;
  std::int64_t* prev_row;
};
// The first position p in the sorted keys of a list (a, b) of m slots with !(key(p) < key), searched
// from a guess as core/history.hpp's lower_bound_key_near: steps doubling away from `guess` until they
// bracket the position, then a binary search between them. A pair's slot in the old list lies near
// its slot's place in the new one (both sorted by (a, b)), a few reads away.
CG_HD std::size_t lower_bound_slot(const std::uint32_t* a, const std::uint32_t* b, std::size_t m,
                                   const PairKey& key, std::size_t guess) {
  if (m == 0) return 0;
  if (guess >= m) guess = m - 1;
  std::size_t lo = 0, hi = m, step = 1;  // the position lies in [lo, hi]
  if (slot_key(a, b, guess) < key) {     // after guess
    lo = guess + 1;
    while (lo + step - 1 < m && slot_key(a, b, lo + step - 1) < key) {
      lo += step;
      step *= 2;
    }
    hi = lo + step - 1 < m ? lo + step - 1 : m;
  } else {  // at or before guess
    hi = guess;
    while (hi >= step && !(slot_key(a, b, hi - step) < key)) {
      hi -= step;
      step *= 2;
    }
    lo = hi >= step ? hi - step + 1 : 0;
  }
  while (lo < hi) {
    const std::size_t mid = lo + (hi - lo) / 2;
    if (slot_key(a, b, mid) < key)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

// `count`: the new list's slots (the guess of slot s in the old list: s scaled to its length).
CG_HD void remap_slot(std::size_t s, const std::uint32_t* na, const std::uint32_t* nb, std::size_t count,
                      const SlotRemap& m) {
  const PairKey key = slot_key(na, nb, s);
  const std::size_t guess =
      count > 0 ? static_cast<std::size_t>(std::uint64_t(s) * std::uint64_t(m.old_count) / count) : 0;
  const std::size_t lo = lower_bound_slot(m.old_a, m.old_b, m.old_count, key, guess);
  if (lo < m.old_count && slot_key(m.old_a, m.old_b, lo) == key && m.old_age[lo] >= 0) {
    m.xi[s] = m.old_xi[lo];
    m.normal[s] = m.old_normal[lo];
    m.age[s] = m.old_age[lo];
    m.prev_row[s] = m.old_rank[lo];
    return;
  }
  m.xi[s] = {0, 0, 0};
  m.normal[s] = {0, 0, 0};
  m.age[s] = -1;
  m.prev_row[s] = -1;
}

}  // namespace cg::dem
