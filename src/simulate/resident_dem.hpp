#pragma once
// contactgrid simulate under mpirun with each rank's bodies where its backend computes (the default;
// CONTACTGRID_SIMULATE_RANKS=host: distributed_dem.hpp's DistributedDem, whose forces run on the host).
// Each rank holds the bodies of its slab (owned) and every body within the ghost width of it
// (ghosts) as the rows of one Simulation (kernels/dem.hpp), in ascending id, on its own GPU with
// --backend cuda: the detection, the forces and the integration of all of them stay there.
//
//   kick_drift (every row) → the ghosts' state (DemRow: with the last step's force and torque) from
//   their owners (only the halo's rows cross the link and MPI) → bounds and the largest displacement
//   since the layout (over the ranks: the frame, the rebuild check) → relayout? (new slabs where the
//   counts drifted apart, the owned bodies with their state and their pairs' springs to their new
//   owners, the new ghosts) → detect, contact terms, body terms, kick (every row)
//
// A step followed by another with nothing between (no log row, frame or contact keys) ends with the
// next one's kick_drift and ghosts' halo overlapping its forces (Simulation::finish_step_sending,
// receive_halo; CONTACTGRID_SIMULATE_OVERLAP=off: never): the edge's contact and body terms (the
// halo's rows, sent and received, and every contact touching one) with their kick and kick_drift,
// the sent rows' records, the records' exchange while the interior's passes run (CUDA: on the
// device), their scatter; the next step then starts at its bounds. Each contact and body is computed
// once by the same function and the interior's passes read no row the halo writes: the same bits.
// A record is what the receiver reads (a sphere's: DemSphereRow, 120 bytes; with ellipsoids, or
// CONTACTGRID_SIMULATE_HALO_BYTES=full, the whole DemRow).
//
// Why the trajectories are the same bits for any rank count: an owned body's contacts are all among
// the held rows (the ghost width is 2 r_max + skin and the rows are laid out again before any body
// moves skin/2), the rows are in id order (so each body's rows as A and as B, and so its sums, come
// in the one-rank order), every held row's state is exact when the contacts are computed (owned by
// induction; ghosts just received), and each pair's spring is exact on the ranks that own one of its
// bodies: there it was computed every step of the pair's life, or brought by the relayout from the
// owner of the pair's smaller id. A ghost's own sums miss its pairs beyond the halo; its state is
// replaced by its owner's before it is read again. Each contact is counted (energies, the contact
// files) by the owner of its smaller id.
//
// A log row (log_sums) sums where the rows are: one rank, its Simulation's energies (CUDA: on the
// device); more ranks, each rank's terms of its owned rows and their contacts as A (CUDA: only those
// downloaded), reduced to the one-rank tree's chunk sums on the rank that holds them
// (rank_records.hpp: tree_sums_on_root), so rank 0 receives about one record per 32 bodies and
// contacts, and the bits stay the one-rank run's. A frame of one rank is its Simulation's bodies; of
// more ranks, each rank's owned rows to rank 0, which keeps its frame's bodies between frames.
// CONTACTGRID_SIMULATE_OUTPUT=gather (the former path): for each log row every owned row's energies
// and contacts to rank 0, and for a frame the owned rows into new bodies on rank 0, at one rank too.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

#include "agreed_stage.hpp"
#include "collectives.hpp"
#include "dem.hpp"
#include "grid_plan.hpp"
#include "resident_steps.hpp"
#include "session.hpp"
#include "simulate/rank_records.hpp"
#include "slab_decomposition.hpp"

namespace cg {

// A body's record between ranks at a relayout: its id and everything that moves with it.
struct ResidentBodyRecord {
  std::int64_t id;
  DemRow row;
};

// A pair's spring between ranks at a relayout.
struct ResidentSpringRecord {
  PairKey key;
  std::int64_t age;
  Vec3<double> xi, normal;
};

template <class Real>
class ResidentDem {
 public:
  ResidentDem(const Session& session, const DemBodies& all, const DemOptions& options)
      : m_session(session), m_all(all), m_options(options), m_walls(options.walls.size()) {
    const std::size_t n = all.size();
    Vec3<double> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    double r_max = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const Vec3<double>& p = all.position[i];
      lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
      hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
      r_max = std::max(r_max, all.radius[i]);
    }
    const Vec3<double> e = hi - lo;
    m_axis = e.x >= e.y && e.x >= e.z ? 0 : (e.y >= e.z ? 1 : 2);
    // the layout's skin: the engine's, times CONTACTGRID_SIMULATE_HALO (>= 1, default 1: a wider halo
    // and fewer relayouts)
    const char* halo = std::getenv("CONTACTGRID_SIMULATE_HALO");
    const double factor = halo ? std::atof(halo) : 1.0;
    if (!(factor >= 1 && factor <= 1000))
      throw UsageError("CONTACTGRID_SIMULATE_HALO must be a number in [1, 1000] (got \"" +
                       std::string(halo ? halo : "") + "\")");
    m_skin = options.engine.skin * factor;
    const char* output = std::getenv("CONTACTGRID_SIMULATE_OUTPUT");
    const std::string how = output ? output : "sums";
    if (how != "sums" && how != "gather")
      throw UsageError("CONTACTGRID_SIMULATE_OUTPUT must be sums or gather (got \"" + how + "\")");
    m_gather = how == "gather";
    const char* ghosts = std::getenv("CONTACTGRID_SIMULATE_GHOSTS");
    const std::string way = ghosts ? ghosts : "halo";
    if (way != "halo" && way != "records")
      throw UsageError("CONTACTGRID_SIMULATE_GHOSTS must be halo or records (got \"" + way + "\")");
    m_ghost_records = way == "records";
    const char* overlap = std::getenv("CONTACTGRID_SIMULATE_OVERLAP");
    const std::string lap = overlap ? overlap : "on";
    if (lap != "on" && lap != "off")
      throw UsageError("CONTACTGRID_SIMULATE_OVERLAP must be on or off (got \"" + lap + "\")");
    m_overlap = lap == "on" && !m_ghost_records;
    const char* bytes = std::getenv("CONTACTGRID_SIMULATE_HALO_BYTES");
    const std::string record = bytes ? bytes : "least";
    if (record != "least" && record != "full")
      throw UsageError("CONTACTGRID_SIMULATE_HALO_BYTES must be least or full (got \"" + record + "\")");
    m_full_records = record == "full";
    m_width = (2 * r_max + m_skin) * (1 + 1e-9);
    std::vector<double> sample(n);
    for (std::size_t i = 0; i < n; ++i) sample[i] = component(all.position[i], m_axis);
    m_slabs.emplace(SlabDecomposition::from_sample(m_axis, sample, session.size()));
    // the held rows of the start: owned and ghosts by the same rule on every rank
    const int me = session.rank();
    std::vector<std::int64_t> ids;
    std::vector<int> owner;
    for (std::size_t i = 0; i < n; ++i) {
      const int o = m_slabs->owner(sample[i]);
      bool held = o == me;
      if (!held) m_slabs->for_each_ghost_rank(sample[i], m_width, [&](int r) { held = held || r == me; });
      if (!held) continue;
      ids.push_back(static_cast<std::int64_t>(i));
      owner.push_back(o);
    }
    DemBodies held = rows_of(ids);
    for (std::size_t k = 0; k < ids.size(); ++k) {
      const std::size_t i = static_cast<std::size_t>(ids[k]);
      held.position[k] = all.position[i];
      if (!all.velocity.empty()) held.velocity[k] = all.velocity[i];
      if (!all.angular_velocity.empty()) held.angular_velocity[k] = all.angular_velocity[i];
      if (!held.orientation.empty()) held.orientation[k] = all.orientation[i];
    }
    Bounds b;
    agreed_stage(m_session, "simulate", [&] {
      b = compute_bounds(BodiesView{all.position, all.radius, {}, {}});
      m_frame = frame_of(b);
    });
    m_ids = ids;
    m_owner = owner;
    agreed_stage(m_session, "simulate", [&] {
      m_sim.emplace(held, options, std::move(ids), m_frame);  // the forces of the start
      halo_plan(held.position);
    });
    check_halo_counts();
  }

  // One step; `another`: the next step follows with nothing between (no log row, frame or keys),
  // so this step may end with the next one's kick_drift and the ghosts' halo overlapping its forces
  // (the overlap: Simulation::finish_step_sending; CONTACTGRID_SIMULATE_OVERLAP=off: never).
  void step(bool another = false) {
    ++m_steps;
    // --stage-times: the host's time of each phase (the device waited for at the step's end)
    auto t = std::chrono::steady_clock::now();
    auto lap = [&](double& into) {
      if (!m_options.stage_times) return;
      const auto now = std::chrono::steady_clock::now();
      into += std::chrono::duration<double>(now - t).count();
      t = now;
    };
    if (!m_ready) {  // the last step ended without this one's kick_drift and halo
      agreed_stage(m_session, "simulate", [&] { m_sim->kick_drift(); });
      exchange_ghosts();
    }
    lap(m_phases.halo);
    ResidentExtent e;
    agreed_stage(m_session, "simulate", [&] {
      try {
        e = m_sim->extent();
      } catch (const InputError& x) {
        throw InputError("step " + std::to_string(m_steps) + ": " + x.what());
      }
    });
    const Bounds global = allgather_bounds(m_session, e.bounds);
    const double moved = m_session.max(e.displacement);
    agreed_stage(m_session, "simulate", [&] { m_frame = frame_of(global); });
    lap(m_phases.frame);
    if (2 * moved > m_skin) {
      const auto t0 = std::chrono::steady_clock::now();
      relayout();
      m_relayout_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
    lap(m_phases.relayout);
    bool overlap = false;
    agreed_stage(m_session, "simulate", [&] { overlap = m_overlap && another && m_sim->can_overlap(); });
    if (overlap) {
      overlapped_forces(lap);
      m_ready = true;
      return;
    }
    agreed_stage(m_session, "simulate", [&] {
      m_sim->finish_step(m_frame);
      if (m_options.stage_times) m_sim->extent();  // waits for the step's device work
    });
    lap(m_phases.forces);
    if (m_options.stage_times) ++m_phases.steps;
    m_ready = false;
  }

  // --stage-times: where this rank's steps went (seconds, summed over `steps` steps): kick-drift and
  // the ghosts' exchange (halo), the bounds and displacement over the ranks (frame), relayouts, and
  // the detection, forces and kick until the device finished them (forces).
  // Overlapped steps (step: `another`): halo is the records' exchange between the ranks (the device
  // runs the interior's forces meanwhile), hidden the part of it the interior's passes covered on
  // the device (CUDA: their events; CPU: none, the interior's passes run after the exchange), forces
  // the detection and the edge's passes until the records were downloaded, then the records' upload
  // (CPU: and the interior's passes) and the wait for the device.
  struct Phases {
    double halo = 0, frame = 0, relayout = 0, forces = 0, hidden = 0;
    std::uint64_t steps = 0, overlapped = 0;
    std::uint64_t halo_rows = 0, halo_bytes = 0;  // sent, over the steps (records of the halo)
  };
  const Phases& phases() const { return m_phases; }

  std::uint64_t steps() const { return m_steps; }
  std::uint64_t rebuilds() const { return m_rebuilds; }
  double relayout_seconds() const { return m_relayout_seconds; }  // this rank's, since the start
  double cell_size() const { return m_frame.cell_size; }
  Backend backend() const { return m_sim->backend(); }
  double skin() const { return m_skin; }

  // Collective: the counts of the final report (StepStats' rebuilds, migrated, owned per rank).
  StepStats loop_stats() {
    StepStats s;
    s.rebuilds = m_rebuilds;
    s.migrated = m_session.sum(m_migrated);
    s.rebalances = m_rebalances;
    const std::vector<std::uint64_t> owned = allgather_counts(m_session, m_owned_rows.size());
    s.owned_min = owned.empty() ? 0 : *std::min_element(owned.begin(), owned.end());
    s.owned_max = owned.empty() ? 0 : *std::max_element(owned.begin(), owned.end());
    return s;
  }

  // Collective: the contacts of the last step over the ranks.
  std::uint64_t contact_count() {
    std::uint64_t mine = 0;
    agreed_stage(m_session, "simulate", [&] { mine = contact_rows().size(); });
    return m_session.sum(mine);
  }

  // Collective: a log row's energies (rank 0; the others: zero) and the contacts of the last step,
  // the same bits as energies() and contact_count() (file comment).
  sim::LogSums log_sums() {
    sim::LogSums out;
    if (m_gather) {
      out.energies = energies();
      out.contacts = contact_count();
      return out;
    }
    if (m_session.size() == 1) {
      agreed_stage(m_session, "simulate", [&] {
        out.energies = m_sim->energies();
        out.contacts = m_sim->contact_count();
      });
      return out;
    }
    const std::size_t p = static_cast<std::size_t>(m_session.size());
    std::vector<DemLogRow> rows;
    std::vector<double> energy;
    std::vector<std::uint64_t> body_at, contact_at;
    std::vector<std::array<double, 3>> body_v;
    std::vector<std::array<double, 1>> contact_v;
    std::vector<sim::IdRun> runs;
    agreed_stage(m_session, "simulate", [&] {
      m_sim->log_terms(m_owned_rows, rows, energy);
      const std::size_t m = rows.size();
      std::vector<std::int64_t> ids(m);
      std::vector<std::uint64_t> counts(m);
      body_at.resize(m);
      body_v.resize(m);
      for (std::size_t j = 0; j < m; ++j) {
        const DemLogRow& r = rows[j];
        if (r.a_end < r.a_begin || r.a_end > energy.size())
          throw Error("simulate: a row's contacts lie outside the step's: internal error");
        ids[j] = m_ids[m_owned_rows[j]];
        counts[j] = r.a_end - r.a_begin;
        body_at[j] = static_cast<std::uint64_t>(ids[j]);
        body_v[j] = {r.kinetic, r.gravity, r.wall};
      }
      runs = sim::id_runs(ids, counts);
    });
    // every rank's runs on every rank: where each rank's contacts lie in the one-rank order
    const std::vector<sim::IdRun> all =
        sim::exchange_records(m_session, repeat(runs, p), std::vector<std::uint64_t>(p, runs.size()));
    std::uint64_t total = 0;
    agreed_stage(m_session, "simulate", [&] {
      const std::vector<std::uint64_t> first = sim::run_offsets(all, runs, m_all.size(), total);
      contact_at.reserve(energy.size());
      contact_v.reserve(energy.size());
      std::size_t j = 0;
      for (std::size_t r = 0; r < runs.size(); ++r) {
        std::uint64_t at = first[r];
        for (; j < rows.size() && body_at[j] < static_cast<std::uint64_t>(runs[r].end); ++j)
          for (std::uint32_t k = rows[j].a_begin; k < rows[j].a_end; ++k) {
            contact_at.push_back(at++);
            contact_v.push_back({energy[k]});
          }
      }
    });
    const std::array<double, 3> b = sim::tree_sums_on_root<3>(m_session, m_all.size(), body_at, body_v);
    const std::array<double, 1> c = sim::tree_sums_on_root<1>(m_session, total, contact_at, contact_v);
    out.energies.kinetic = b[0];
    out.energies.gravity = b[1];
    out.energies.elastic = c[0] + (m_walls > 0 ? b[2] : 0.0);
    out.contacts = total;
    return out;
  }

  // Collective: every body on rank 0 in id order, over `start` (the others: empty), valid until the
  // next call: over several ranks rank 0 keeps its frame's bodies and takes only their motion again.
  const DemBodies& gather_bodies(const DemBodies& start) {
    if (!m_gather && m_session.size() == 1) {  // every body is a row, in id order
      agreed_stage(m_session, "simulate", [&] { m_frame_bodies = m_sim->bodies(); });
      return m_frame_bodies;
    }
    std::vector<sim::BodyOut> mine(m_owned_rows.size());
    agreed_stage(m_session, "simulate", [&] {
      std::vector<DemRow> rows;
      m_sim->read_rows(m_owned_rows, rows);
      const std::ptrdiff_t m = static_cast<std::ptrdiff_t>(rows.size());
#pragma omp parallel for schedule(static) if (m > 65536)
      for (std::ptrdiff_t k = 0; k < m; ++k) {
        const std::size_t j = static_cast<std::size_t>(k);
        mine[j] = {m_ids[m_owned_rows[j]], rows[j].position, rows[j].velocity, rows[j].omega,
                   rows[j].orientation};
      }
    });
    if (m_gather)
      m_frame_bodies = sim::bodies_on_root(m_session, mine, start);  // a new one each frame
    else
      sim::bodies_on_root(m_session, mine, start, m_frame_bodies);
    return m_frame_bodies;
  }

  // Collective: the energies on rank 0, summed in the one-rank order.
  DemEnergies energies() {
    std::vector<sim::EnergyOut> mine;
    std::vector<sim::ContactOut<Real>> rows;
    agreed_stage(m_session, "simulate", [&] {
      const DemState st = m_sim->state();
      mine.resize(m_owned_rows.size());
      for (std::size_t j = 0; j < m_owned_rows.size(); ++j) {
        const std::size_t k = m_owned_rows[j];
        const std::size_t i = static_cast<std::size_t>(m_ids[k]);
        const bool ell = !m_all.shape.empty() && m_all.shape[i] == Shape::ellipsoid;
        const dem::BodyProps p = props(i);
        const DemRow& r = st.rows[k];
        const dem::BodyState s{r.position,
                               r.velocity,
                               r.omega,
                               ell ? r.momentum : Vec3<double>{0, 0, 0},
                               ell ? r.orientation : Quat<double>{1, 0, 0, 0},
                               r.force,
                               r.torque};
        mine[j] = {m_ids[k], dem::kinetic_energy(s, p, ell), -p.mass * dot(m_options.gravity, s.position),
                   m_walls > 0 ? st.wall_energy[k] : 0.0};
      }
      rows = contact_rows(&st.contact_energy);
    });
    return sim::energies_on_root(m_session, mine, rows, m_walls > 0);
  }

  // Collective: the last step's contacts on rank 0 (sim::contacts_on_root).
  Contacts<Real> gather_contacts(const std::vector<PairKey>& previous) {
    std::vector<sim::ContactOut<Real>> rows;
    agreed_stage(m_session, "simulate", [&] { rows = contact_rows(); });
    return sim::contacts_on_root(m_session, rows, previous);
  }

  // Collective: the keys of the last step's contacts on rank 0, sorted.
  std::vector<PairKey> gather_keys() {
    std::vector<PairKey> keys;
    agreed_stage(m_session, "simulate", [&] {
      for (const sim::ContactOut<Real>& r : contact_rows()) keys.push_back({r.a, r.b});
    });
    return sim::keys_on_root(m_session, keys);
  }

 private:
  Frame frame_of(const Bounds& b) const {
    const EngineOptions& o = m_options.engine;
    return make_frame(b, o.cell_size, precision_of<Real>(), o.cell_choice);
  }

  dem::BodyProps props(std::size_t i) const {
    const bool ell = !m_all.shape.empty() && m_all.shape[i] == Shape::ellipsoid;
    return dem::body_props(ell ? Shape::ellipsoid : Shape::sphere, m_all.radius[i],
                           ell ? m_all.semi_axes[i] : Vec3<double>{0, 0, 0}, m_options.material.density);
  }

  // The rows of bodies `ids` (ascending) with what does not move (radii, shape rows) from the scene;
  // their motion zero (the caller's).
  DemBodies rows_of(const std::vector<std::int64_t>& ids) const {
    DemBodies b;
    const std::size_t m = ids.size();
    const bool shapes = m_all.has_ellipsoids();
    b.position.assign(m, {0, 0, 0});
    b.velocity.assign(m, {0, 0, 0});
    b.angular_velocity.assign(m, {0, 0, 0});
    b.radius.resize(m);
    if (shapes) {
      b.shape.resize(m);
      b.semi_axes.resize(m);
      b.orientation.assign(m, {1, 0, 0, 0});
    }
    if (!m_all.fixed.empty()) b.fixed.resize(m);
    for (std::size_t k = 0; k < m; ++k) {
      const std::size_t i = static_cast<std::size_t>(ids[k]);
      b.radius[k] = m_all.radius[i];
      if (shapes) {
        b.shape[k] = m_all.shape[i];
        b.semi_axes[k] = m_all.semi_axes[i];
      }
      if (!m_all.fixed.empty()) b.fixed[k] = m_all.fixed[i];
    }
    return b;
  }

  // The halo of the layout from the held rows' owners and positions: each owned row to every rank
  // whose slab is within the ghost width (ascending id), and the ghosts by owner (ascending id).
  void halo_plan(const std::vector<Vec3<double>>& position) {
    const int me = m_session.rank();
    const std::size_t p = static_cast<std::size_t>(m_session.size());
    std::vector<std::vector<std::uint32_t>> to(p), from(p);
    m_owned_rows.clear();
    for (std::size_t k = 0; k < m_ids.size(); ++k) {
      const auto row = static_cast<std::uint32_t>(k);
      if (m_owner[k] != me) {
        from[static_cast<std::size_t>(m_owner[k])].push_back(row);
        continue;
      }
      m_owned_rows.push_back(row);
      m_slabs->for_each_ghost_rank(component(position[k], m_axis), m_width,
                                   [&](int r) { to[static_cast<std::size_t>(r)].push_back(row); });
    }
    m_send_rows.clear();
    m_recv_rows.clear();
    m_send_counts.assign(p, 0);
    m_recv_counts.assign(p, 0);
    for (std::size_t r = 0; r < p; ++r) {
      m_send_counts[r] = to[r].size();
      m_recv_counts[r] = from[r].size();
      m_send_rows.insert(m_send_rows.end(), to[r].begin(), to[r].end());
      m_recv_rows.insert(m_recv_rows.end(), from[r].begin(), from[r].end());
    }
    if (!m_ghost_records) m_sim->set_halo(m_send_rows, m_recv_rows, m_full_records);
  }

  // Collective, once a layout: what the owners will send each step is what this rank holds as ghosts
  // (every rank stops together otherwise, none waiting for a message).
  void check_halo_counts() {
    const std::vector<std::uint64_t> from = alltoall_counts(m_session, m_send_counts);
    agreed_stage(m_session, "simulate", [&] {
      if (from != m_recv_counts)
        throw Error("simulate: the owners send other ghost rows than this rank holds: internal error");
    });
  }

  // The ghosts' state from their owners (the halo's rows only): gathered where the rows are into a
  // reused page-locked buffer, sent from it straight into the receivers' (each rank receives from
  // each owner its ghosts in ascending id, the order the owner sends them), scattered into the
  // ghosts' rows. CONTACTGRID_SIMULATE_GHOSTS=records: the former path (the rows' indices uploaded,
  // the records downloaded into and uploaded from pageable vectors, every step).
  void exchange_ghosts() {
    if (!m_ghost_records) {
      const std::byte* out = nullptr;
      std::byte* in = nullptr;
      agreed_stage(m_session, "simulate", [&] {
        out = m_sim->gather_halo();
        in = m_sim->halo_inbox();
      });
      alltoallv_records(m_session, m_sim->halo_record_bytes(), out, m_send_counts, in, m_recv_counts);
      count_halo(m_sim->halo_record_bytes());
      agreed_stage(m_session, "simulate", [&] { m_sim->scatter_halo(); });
      return;
    }
    std::vector<DemRow> send;
    agreed_stage(m_session, "simulate", [&] { m_sim->read_rows(m_send_rows, send); });
    const std::vector<DemRow> got = sim::exchange_records(m_session, send, m_send_counts);
    count_halo(sizeof(DemRow));
    agreed_stage(m_session, "simulate", [&] {
      if (got.size() != m_recv_rows.size())
        throw Error("simulate: " + std::to_string(got.size()) + " ghost rows came for " +
                    std::to_string(m_recv_rows.size()) + " ghosts: internal error");
      m_sim->write_rows(m_recv_rows, got);
    });
  }

  // The step's forces with the ghosts' halo between their two passes (Simulation::finish_step_sending):
  // the edge's forces and the sent rows' records, the records to their ranks while the device runs
  // the interior's, the received records into the ghosts' rows. The rows end drifted for the next
  // step, the ghosts current (m_ready).
  template <class Lap>
  void overlapped_forces(Lap& lap) {
    const std::byte* out = nullptr;
    std::byte* in = nullptr;
    agreed_stage(m_session, "simulate", [&] {
      out = m_sim->finish_step_sending(m_frame);
      in = m_sim->halo_inbox();
    });
    lap(m_phases.forces);
    const auto t0 = std::chrono::steady_clock::now();
    alltoallv_records(m_session, m_sim->halo_record_bytes(), out, m_send_counts, in, m_recv_counts);
    count_halo(m_sim->halo_record_bytes());
    const double exchange = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    lap(m_phases.halo);
    // CUDA: the upload and scatter enqueued; CPU: the scatter, then the interior's passes
    agreed_stage(m_session, "simulate", [&] { m_sim->receive_halo(); });
    if (!m_options.stage_times) return;
    agreed_stage(m_session, "simulate", [&] {
      m_phases.hidden += std::min(exchange, m_sim->interior_seconds());
      m_sim->extent();  // waits for the step's device work
    });
    lap(m_phases.forces);
    ++m_phases.steps;
    ++m_phases.overlapped;
  }

  void count_halo(std::size_t record_bytes) {
    if (!m_options.stage_times) return;
    m_phases.halo_rows += m_send_rows.size();
    m_phases.halo_bytes += m_send_rows.size() * record_bytes;
  }

  std::size_t held_row(std::int64_t id) const {
    const auto at = std::lower_bound(m_ids.begin(), m_ids.end(), id);
    if (at == m_ids.end() || *at != id)
      throw Error("simulate: body " + std::to_string(id) + " is not held by this rank: internal error");
    return static_cast<std::size_t>(at - m_ids.begin());
  }

  // New slabs from the owned centres where needed, the owned bodies and their pairs' springs to their new
  // owners, the new ghosts; the rows set again.
  void relayout();  // (resident_relayout.hpp)

  template <class T>
  static std::vector<T> repeat(const std::vector<T>& v, std::size_t times) {
    std::vector<T> out;
    out.reserve(v.size() * times);
    for (std::size_t t = 0; t < times; ++t) out.insert(out.end(), v.begin(), v.end());
    return out;
  }

  // This rank's contacts of the last step (those whose smaller id it owns), global ids, with their
  // energies where given (the state's, in the contacts' order).
  std::vector<sim::ContactOut<Real>> contact_rows(const std::vector<double>* energy = nullptr) {
    const Contacts<Real>& c = m_sim->contacts();
    std::vector<sim::ContactOut<Real>> rows;
    for (std::size_t k = 0; k < c.size(); ++k) {
      const std::size_t a = static_cast<std::size_t>(c.id_a[k]), b = static_cast<std::size_t>(c.id_b[k]);
      if (m_owner[a] != m_session.rank()) continue;
      rows.push_back({m_ids[a], m_ids[b], c.age[k], c.position_on_a[k], c.position_on_b[k], c.normal_on_b[k],
                      c.distance[k], energy && k < energy->size() ? (*energy)[k] : 0.0});
    }
    return rows;
  }

  const Session& m_session;
  const DemBodies& m_all;
  DemOptions m_options;
  std::size_t m_walls;
  int m_axis = 0;
  double m_skin = 0, m_width = 0;
  std::optional<SlabDecomposition> m_slabs;
  Frame m_frame{};
  std::optional<Simulation<Real>> m_sim;
  // the held rows: global ids (ascending) and owners; the owned rows, the halo's rows to send (by
  // destination rank) and the ghosts' rows to receive (by source rank)
  std::vector<std::int64_t> m_ids;
  std::vector<int> m_owner;
  std::vector<std::uint32_t> m_owned_rows, m_send_rows, m_recv_rows;
  std::vector<std::uint64_t> m_send_counts, m_recv_counts;
  bool m_ghost_records = false;  // CONTACTGRID_SIMULATE_GHOSTS=records (exchange_ghosts)
  bool m_overlap = true;         // CONTACTGRID_SIMULATE_OVERLAP (step)
  bool m_full_records = false;   // CONTACTGRID_SIMULATE_HALO_BYTES=full (halo_plan)
  // the rows hold this step's kick_drift and the ghosts their owners' state (an overlapped step ended)
  bool m_ready = false;
  std::uint64_t m_steps = 0, m_rebuilds = 0, m_migrated = 0, m_rebalances = 0;
  double m_relayout_seconds = 0;
  Phases m_phases;
  bool m_gather = false;     // CONTACTGRID_SIMULATE_OUTPUT=gather (file comment)
  DemBodies m_frame_bodies;  // gather_bodies' (rank 0)
};

}  // namespace cg

#include "simulate/resident_relayout.hpp"  // (ResidentDem::relayout)
