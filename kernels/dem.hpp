#pragma once
// Granular dynamics on the engine (contactgrid simulate): spheres and ellipsoids of one material,
// Hertz–Mindlin contacts with a tangential spring carried by the contact identity, gravity and walls,
// the synchronised velocity-Verlet step (core/dem_body.hpp), on the CPU or CUDA backend over the same
// core math (core/dem_step.hpp), CPU = CUDA bit for bit. g++-safe public header.
//
// A step: kick_drift (bodies) → detect (the engine, with EngineOptions::history: contacts carry
// their previous row) → contact_terms (per contact) → order by B + body_terms (per body, sums in a
// fixed order, walls, gravity) → kick (bodies). On the CUDA backend every array stays on the device
// (the engine's device-resident contacts); the host sees the state only when it asks (bodies(),
// contacts(), energies()). CONTACTGRID_DEM_PATH=slots: scenes of spheres on one rank with a fixed skin
// take the slots path instead (dem_slots.hpp: one pass per body over the kept candidate list, a
// contact's spring in the list's slot, no contact rows unless asked; the same bits).
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/dem_contact.hpp"
#include "core/dem_walls.hpp"
#include "engine.hpp"

namespace cg {

// Bodies in id order (host): spheres have Shape::sphere (or `shape` empty: all spheres), ellipsoids
// their semi-axes and orientation; radius: a sphere's radius, an ellipsoid's largest semi-axis.
// velocity, angular_velocity: world frame (empty: zero). fixed: 1 for a body that does not move (an
// obstacle; empty: none).
struct DemBodies {
  std::vector<Vec3<double>> position, velocity, angular_velocity;
  std::vector<double> radius;
  std::vector<Shape> shape;
  std::vector<Vec3<double>> semi_axes;
  std::vector<Quat<double>> orientation;
  std::vector<std::uint8_t> fixed;
  std::size_t size() const { return position.size(); }
  bool has_ellipsoids() const;
};

struct DemOptions {
  dem::Material material;
  Vec3<double> gravity{0, 0, 0};
  std::vector<dem::Wall> walls;
  double dt = 0;             // > 0 (time_step_limits says what is stable)
  bool synchronized = true;  // false: plain velocity Verlet (for comparison)
  EngineOptions engine;      // backend, skin, threads, device (history is set on)
  // Time each stage of every step (Simulation::stage_times). CUDA: events on the device's timeline,
  // and the host waits for each step's last one (one synchronisation a step more).
  bool stage_times = false;
};

// Where the steps' time went (DemOptions::stage_times), summed over `steps` steps: `step` the
// stages of a step in order (kick_drift, detect, contact_terms, body_index, body_terms, kick; the CPU
// backend times body_index within body_terms), `detection` the engine's own stages of each detect
// (EngineStats' names), `energy_seconds` the energies() calls (log rows; not in the steps).
struct DemStageTimes {
  std::uint64_t steps = 0;
  StageTimes step, detection;
  double energy_seconds = 0;
  std::uint64_t energy_calls = 0;
};

// The time scales of a scene (dt auto and the warning for a given dt): Rayleigh's wave time of the
// smallest body, T_R = π r √(ρ/G) / (0.1631 ν + 0.8766), and Hertz's contact time of two smallest
// bodies meeting at `speed` (2.87 (m*²/(R* E*² v))^{1/5}). auto: min(0.2 T_R, t_H / 40).
struct TimeStepLimits {
  double rayleigh = 0, hertz = 0, automatic = 0;
};
TimeStepLimits time_step_limits(const DemBodies& bodies, const dem::Material& m, double speed);

// The restitution of the force law with damping α (core/dem_contact.hpp: one dimensionless
// collision integrated numerically), and its inverse (bisection). UsageError when e is outside
// (0, 1] or below what the damping can reach.
double restitution_for_damping(double alpha);
double damping_for_restitution(double restitution);

// Checks a material, a time step and walls (UsageError naming the option) and the bodies (InputError
// naming the body: non-finite motion, a body inside a wall at the start).
void check_dem_setup(const DemBodies& bodies, const DemOptions& options);

// Energies of the current state: kinetic (translation + rotation), potential of gravity (−Σ m g·x)
// and elastic (contacts and walls), each summed in a fixed order (CPU = CUDA).
struct DemEnergies {
  double kinetic = 0, gravity = 0, elastic = 0;
  double potential() const { return gravity + elastic; }
  double total() const { return kinetic + gravity + elastic; }
};

// A body's state as a rank of a run over several ranks sends it to the ranks that hold the body as
// a ghost (src/simulate/resident_dem.hpp): what a step and a contact read of it, its force and
// torque (the last step's: the synchronised velocities of its contacts read them) included.
struct DemRow {
  Vec3<double> position, velocity, omega, momentum;  // a sphere's momentum: unread
  Quat<double> orientation;                          // a sphere's: unread
  Vec3<double> force, torque;
};

// A sphere's record in the halo (Simulation::set_halo): DemRow less the angular momentum and
// orientation a sphere never reads (120 bytes against 176).
struct DemSphereRow {
  Vec3<double> position, velocity, omega, force, torque;
};

// What a Simulation's rows carry from a step to the next (host): each row's state, wall springs
// (rows × walls, row-major) and wall energy; the last step's contacts'
// identity (history: pair keys by the rows' ids, ages) with each pair's spring, normal and energy,
// in the history's order.
struct DemState {
  std::vector<DemRow> rows;
  std::vector<Vec3<double>> wall_xi;
  std::vector<double> wall_energy;
  ContactHistory history;
  std::vector<Vec3<double>> xi, normal;
  std::vector<double> contact_energy;
};

// What a log row needs of one row of a rank (Simulation::log_terms): its energies (kinetic, of
// gravity, of its walls' springs) and the run [a_begin, a_end) of its contacts as A in the last
// step's contacts (in contact order: the contacts by A, then by B).
struct DemLogRow {
  double kinetic, gravity, wall;
  std::uint32_t a_begin, a_end;
};

template <class Real>
class Simulation {
 public:
  Simulation(const DemBodies& bodies, const DemOptions& options);
  ~Simulation();
  Simulation(Simulation&&) noexcept;
  Simulation& operator=(Simulation&&) noexcept;

  // `steps` steps. InputError naming the body and step when a body's state stops being finite.
  void run(std::uint64_t steps);
  std::uint64_t steps() const;  // taken since the start
  double time() const;          // steps() · dt

  DemBodies bodies();                 // the current state (CUDA: downloaded)
  const Contacts<Real>& contacts();   // the last step's contacts, with history (CUDA: downloaded)
  std::size_t contact_count() const;  // of the last step
  DemEnergies energies();             // of the current state (after the last step's forces)
  const EngineStats& engine_stats() const;
  const StageTimes& engine_times() const;
  DemStageTimes stage_times() const;  // DemOptions::stage_times; empty without it
  Backend backend() const;
  double alpha() const;  // the damping of the restitution

  // ---- one rank's rows of a run over several ranks (src/simulate/resident_dem.hpp) ----------------
  // The rows' global ids (strictly ascending: the contact history's keys; the contacts' ids stay row
  // indices) and the frame of every detection (the run's, the same on every rank), from the start.
  Simulation(const DemBodies& bodies, const DemOptions& options, std::vector<std::int64_t> ids,
             std::optional<Frame> frame);
  // A step in two halves with the ghosts' exchange between: kick_drift of every row (nothing where
  // the rows already hold it: after receive_halo); then the detection in `frame`, the forces and the
  // kick (the same bits as run(1)).
  void kick_drift();
  void finish_step(std::optional<Frame> frame);
  // The state (DemRow) of rows `rows` out (CUDA: gathered and downloaded) and in (uploaded, scattered).
  void read_rows(const std::vector<std::uint32_t>& rows, std::vector<DemRow>& out);
  void write_rows(const std::vector<std::uint32_t>& rows, const std::vector<DemRow>& in);
  // The rows' bounds (validated as compute_bounds, a bad row named by its id) and the largest
  // displacement of a row since the rows were set.
  ResidentExtent extent();
  // Everything the rows carry (CUDA: downloaded); set_rows replaces the rows by `bodies` with their
  // ids and what they carry (the same rows' count in every array of `state`).
  DemState state();
  // A log row's terms of rows `rows` (DemLogRow, computed where the rows are: CUDA downloads only
  // these) and the energy of each of the last step's contacts (contact order).
  void log_terms(const std::vector<std::uint32_t>& rows, std::vector<DemLogRow>& out,
                 std::vector<double>& contact_energy);
  // The halo of a run over several ranks: set_halo keeps the rows sent and the rows received each
  // step (CUDA: on the device) until the rows are set again; gather_halo gives the sent rows' records
  // (CUDA: gathered on the device into a reused page-locked buffer; valid until the next call),
  // halo_inbox the place for the received rows' records, which scatter_halo writes into their rows.
  // A record is what the receiver's steps read of the row, halo_record_bytes() each: DemSphereRow
  // where the rows hold no ellipsoid, else (or with full_records) DemRow.
  void set_halo(const std::vector<std::uint32_t>& send, const std::vector<std::uint32_t>& receive,
                bool full_records = false);
  std::size_t halo_record_bytes() const;
  const std::byte* gather_halo();
  std::byte* halo_inbox();
  void scatter_halo();
  // The step's second half with the halo overlapping its forces (the halo set; can_overlap): the
  // detection in `frame`, then the forces in two passes (dem::Pass): the edge's (the halo's rows,
  // sent and received, and every contact touching one) with their kick and the next step's
  // kick_drift; the sent rows' records gathered (as gather_halo) and returned; the interior's (every
  // other row and contact) with the same kick and kick_drift. After the caller fills halo_inbox,
  // receive_halo scatters it into the ghosts' rows. CUDA: the interior's passes run on the device
  // while the records are downloaded, exchanged and uploaded (the records on a stream of their own;
  // the device's later work ordered after their scatter); CPU: the interior's after the scatter. The
  // same bits as finish_step, kick_drift, gather_halo, scatter_halo: each contact and body is
  // computed once by the same function, and the interior's reads no row the halo writes.
  bool can_overlap() const;
  const std::byte* finish_step_sending(std::optional<Frame> frame);
  void receive_halo();
  // DemOptions::stage_times: the device's seconds in the last overlapped step's interior passes
  // after the sent records were downloaded (CUDA; waits for them), what the records' exchange between
  // the ranks can hide behind; CPU: 0 (they run after it).
  double interior_seconds();
  void mark_rows();  // the displacement counts from here (set_rows of the same rows, nothing moved)
  void set_rows(const DemBodies& bodies, std::vector<std::int64_t> ids, const DemState& state);
  const std::vector<std::int64_t>& ids() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> m_impl;
};

extern template class Simulation<float>;
extern template class Simulation<double>;

}  // namespace cg
