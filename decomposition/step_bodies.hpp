#pragma once
// The bodies of the resident steps (comm/resident_steps): a rank's owned bodies in ascending id, with
// any per-body state the caller attaches, and the steps' motion rule (detect --steps N --spin W).
// Pure host code (no MPI, no CUDA).
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <span>
#include <vector>

#include "assemble.hpp"
#include "engine.hpp"

namespace cg {

// A rank's owned bodies, ascending id: the state of a simulation between steps. The caller moves
// them (position, orientation) between steps; each body's `state_bytes` bytes of `state` (the
// caller's: a velocity, a reference pose) stay with it.
struct StepBodies {
  HostVector<Vec3<double>> position;
  HostVector<double> radius;  // the bounding radius (an ellipsoid's largest semi-axis)
  HostVector<std::int64_t> id;
  ShapeRows shapes;  // empty: every body is a sphere
  std::size_t state_bytes = 0;
  HostVector<std::byte> state;  // body k's at [k·state_bytes, (k+1)·state_bytes)

  std::size_t size() const { return radius.size(); }
  BodiesView view() const {
    return BodiesView{position, radius, id, {}, shapes.shape, shapes.semi_axes, shapes.orientation};
  }
};

// Bodies with room for n rows (left as they are): shape rows when `shapes`, state of `state_bytes`
// a body.
StepBodies sized_step_bodies(std::size_t n, bool shapes, std::size_t state_bytes = 0);

// `b` resized to n rows in place (storage kept when it has room: a rank's bodies change by a few rows
// at a rebuild), shape rows when `shapes`, state of `state_bytes` a body; rows are left as they are.
void resize_step_bodies(StepBodies& b, std::size_t n, bool shapes, std::size_t state_bytes);

// A migration's new rows: `from`'s rows except those in `leaving` (row indices, strictly ascending)
// merged by id with `arrivals` (strictly ascending id), into `into` (resized in place: its storage is
// the spare of the previous migration). The runs of rows between the changes are copied in parallel
// (splice_rows.hpp); nothing is sorted. Returns each arrival's place: the row of `from` it goes before
// (Engine::splice_resident makes the same change to an engine's rows). Error (internal) when an
// arrival's id is held by a row that stays, or an input is not ascending. Shape rows: `into` has them
// when `shapes` (then every source with rows has them).
std::vector<std::size_t> merge_step_bodies(const StepBodies& from, std::span<const std::size_t> leaving,
                                           const StepBodies& arrivals, bool shapes, StepBodies& into,
                                           int threads);

// Where row i of a migration's new rows comes from, without making them: merge_step_bodies' rows
// read in place (the step loop lays out from the few rows it needs while the merge runs beside it).
// `leaving` and `before` as merge_step_bodies takes and returns them, `n` the rows of `from`.
class SpliceMap {
 public:
  struct Source {
    bool arrival;  // row `row` of the arrivals, else of `from`
    std::size_t row;
  };
  SpliceMap() = default;
  SpliceMap(std::size_t n, std::span<const std::size_t> leaving, std::span<const std::size_t> before);
  std::size_t size() const { return m_size; }
  Source operator()(std::size_t i) const;  // i < size()

 private:
  std::size_t m_size = 0;
  std::vector<std::size_t> m_arrival_row;  // arrival j's new row (ascending)
  std::vector<std::size_t> m_gap;          // leaving[j] - j (non-decreasing)
  // per bucket of 2^k_bucket_bits rows: the first arrival row and the first gap at or above its first
  // row, so that a lookup scans a few entries instead of two binary searches (the layout looks up
  // every row it reads while the merge runs)
  static constexpr unsigned k_bucket_bits = 12;
  std::vector<std::size_t> m_arrival_from, m_gap_from;
};

// merge_step_bodies in two parts: the arrivals' places (the checks: the Errors above), then the rows
// copied (what the step loop runs beside its layout).
std::vector<std::size_t> arrival_places(const StepBodies& from, std::span<const std::size_t> leaving,
                                        const StepBodies& arrivals, bool shapes, int threads = 1);
void splice_step_bodies(const StepBodies& from, std::span<const std::size_t> leaving,
                        std::span<const std::size_t> before, const StepBodies& arrivals, bool shapes,
                        StepBodies& into, int threads);

// The owned rows (report mask set, or every row when ids are implied) of an engine input.
StepBodies owned_bodies(const EngineInput& in, int threads);

// How the CLI's steps move the bodies. Default: not at all (the file's contacts every step).
struct StepMotion {
  // Radians per step: at step s (1 … N) every ellipsoid's orientation is spun_orientation(id, q0,
  // spin·s); spheres do not turn. 0: the bodies keep the file's orientations.
  double spin = 0;
  // World length per step: at step s every body's centre is drifted_position(id, c0, drift, s) = its
  // file centre c0 + s·drift·u(id), u the unit vector drift_direction(id): bodies cross the slabs'
  // cuts and leave the box. 0: the bodies keep the file's centres.
  double drift = 0;
  // The ghosts' semi-axes travel with their orientations every step (a simulation whose shapes grow;
  // its bounding radii travel already). Here they never change: off, they go once, at setup.
  bool send_semi_axes = false;
  // Off only to show that the check catches stale ghosts (tests): B's shape rows keep the first
  // exchange's, as if the steps refreshed positions and radii alone.
  bool refresh_shapes = true;
  // Every step's contacts hashed (contacts_hash, summed over ranks: StepStats::step_hashes), so that
  // tests compare every step with a detection from scratch. CUDA: a download per step.
  bool hash_every_step = false;
  // Called on every rank after each step with the number of steps done (a progress line; empty: none).
  std::function<void(int)> on_step;
  // The halo's rule. On (detect's steps): each body's ghost width from its radius (GhostRule, the run's
  // per-body halo plus the skin): a large body goes to every slab it reaches, a small one only as far
  // as small partners need it, and a pair crossing a cut is reported by the owner of its anchor
  // (bodies.hpp: the narrow body of a wide and a narrow one). Off: one width for every body (2·r_max
  // plus the skin), each such pair reported by the owner of its smaller id (contactgrid simulate
  // computes a contact's terms there).
  bool ghosts_by_radius = false;
  // Over several ranks, how many of the engines' skins a layout lasts (its ghost width's margin and
  // the rebuild check's): the engines rebuild their candidate lists at their own checks in between,
  // without a migration and a layout (>= 1; 1: every build lays the rows out; one rank: always 1).
  // Measured on two GPUs (BENCHMARKS §36), 2 gains within the runs' spread and 3 loses (more ghosts,
  // and the skin tuner's fits mix builds with and without a layout). CONTACTGRID_STEP_LAYOUT_SKIN=k
  // overrides it.
  double layout_skins = 1;
};

// An order-free fingerprint of a contact pair; a contact set's is the sum over its pairs.
std::uint64_t pair_hash(std::int64_t a, std::int64_t b);

// The spin's rule: body `id`'s orientation `q0` turned by `angle` radians (world frame) about a unit
// axis fixed per body, uniform on the sphere as a pure function of the id (pair_hash of (id, 1) and
// (id, 2)). Any rank computes any body's orientation at any step from the id alone.
Vec3<double> spin_axis(std::int64_t id);
Quat<double> spun_orientation(std::int64_t id, Quat<double> q0, double angle);

// The drift's rule: body `id`'s centre at step `step` from its file centre `c0`: c0 + u·(drift·step),
// u = drift_direction(id) a unit vector uniform on the sphere as a pure function of the id (pair_hash
// of (id, 3) and (id, 4)). Any rank computes any body's centre at any step from the id alone.
Vec3<double> drift_direction(std::int64_t id);
Vec3<double> drifted_position(std::int64_t id, Vec3<double> c0, double drift, int step);

// An order-free fingerprint of a contact set that covers every field: the sum over the rows of a
// hash of the row's ids and the bits of its other fields (the optional ones when `c.full`).
template <class Real>
std::uint64_t contacts_hash(const Contacts<Real>& c);

// The pose a body had in the file: the state the CLI's steps attach to every body, from which
// move_bodies computes the pose of any step.
struct FilePose {
  Vec3<double> position;
  Quat<double> orientation;
};

// The state a body carries for its file pose: a FilePose, or in a scene without ellipsoids the centre
// alone (24 of 56 bytes: a migration's merge copies every row's state, BENCHMARKS §36).
constexpr std::size_t file_pose_bytes(bool orientations) {
  return orientations ? sizeof(FilePose) : sizeof(Vec3<double>);
}

// Attaches each body's current pose as its state (state_bytes = file_pose_bytes(orientations)).
// `orientations`: the scene has ellipsoids (the same on every rank, as a migration moves the state
// between ranks; the bodies then have shape rows).
void attach_file_poses(StepBodies& bodies, bool orientations, int threads);

// What a motion changed.
struct Moved {
  bool positions = false, orientations = false;
};

// The bodies' poses at step `step` of `motion` from their attached FilePose (a drift moves every
// centre; a spin turns the ellipsoids).
Moved move_bodies(StepBodies& bodies, const StepMotion& motion, int step, int threads);

}  // namespace cg
