// The step loop (see resident_steps.hpp): the rows of the steps, then each step's stages.
#include "resident_steps.hpp"

#include <algorithm>
#include <array>
#include <optional>
#include <thread>

#include "agreed_stage.hpp"
#include "step_plan.hpp"
#include "timing.hpp"
#include "transport.hpp"

namespace cg {
namespace {

// Page-locked host memory for an engine's copies (released before the memory is).
template <class Real>
struct Pin {
  Engine<Real>& engine;
  void* p;
  bool pinned;
  Pin(Engine<Real>& e, void* ptr, std::size_t bytes) : engine(e), p(ptr), pinned(e.pin_host(ptr, bytes)) {}
  ~Pin() {
    if (pinned) engine.unpin_host(p);
  }
  Pin(const Pin&) = delete;
  Pin& operator=(const Pin&) = delete;
};

// A boundary row as a step sends it in a scene with ellipsoids: the orientation in the same message
// as the position and bounding radius (64 bytes; a sphere-only scene sends BodyRecords, 40).
struct OrientedRecord {
  Vec3<double> position;
  double radius;
  Quat<double> orientation;
};

}  // namespace

const char* to_string(StepStage stage) {
  switch (stage) {
    case StepStage::halo:
      return "halo";
    case StepStage::interior:
      return "interior";
    case StepStage::boundary:
      return "boundary";
    case StepStage::step:
      return "step";
  }
  return "?";
}

template <class Real>
struct StepLoop<Real>::State {
  Session& session;
  detail::Comm comm;
  Engine<Real>& a;  // engine A: the owned bodies
  Frame frame;
  SlabDecomposition slabs;
  double width;
  StepMotion motion;
  int threads;
  bool shapes = false;   // the scene has ellipsoids (agreed over the ranks)
  bool refresh = false;  // every step refreshes the ghosts' orientations
  bool grow = false;     // ... and their semi-axes

  StepBodies bodies;  // owned, ascending id
  StepPlan plan;      // of the owned rows: interior or boundary, and the halo
  BoundaryRows rows;  // engine B's row of each boundary row and each ghost
  std::vector<std::uint64_t> send_counts, recv_counts;
  // engine B's rows, host side (page-locked while B lives)
  HostVector<Vec3<double>> b_p;
  HostVector<double> b_r;
  HostVector<std::int64_t> b_id;
  HostVector<Quat<double>> b_q;     // scenes with ellipsoids
  HostVector<Vec3<double>> b_semi;  // when the semi-axes travel (StepMotion::send_semi_axes)
  std::optional<Engine<Real>> b;    // engine B: only when this rank has boundary rows
  std::optional<Pin<Real>> pin_p, pin_r, pin_q;
  std::uint64_t halo_rows = 0;  // ghosts received per step
  double setup = 0;

  // the step in flight
  std::thread interior;
  std::exception_ptr error, interior_error;
  WallClock::time_point s0;
  std::uint64_t found_a = 0, found_b = 0;
  std::array<double, kStepStageCount> t{};

  // every step's
  std::vector<std::array<double, kStepStageCount>> times;
  std::vector<std::vector<double>> engine_times;  // engine A's stages, by engine_stage_names()
  std::vector<std::uint64_t> found;               // this rank's contacts
  std::vector<std::uint64_t> found_all;           // summed over ranks (contacts_per_step)

  State(Session& s, Engine<Real>& e, const Frame& f, const SlabDecomposition& sl, double w,
        const StepMotion& m, int th)
      : session(s), comm(s), a(e), frame(f), slabs(sl), width(w), motion(m), threads(th) {}
  ~State() {
    if (interior.joinable()) interior.join();
  }

  void fail() {
    if (!error) error = std::current_exception();
  }

  // Engine B's rows from the bodies' boundary rows and the ghosts' records (the first exchange).
  void make_engine_b(const HostVector<BodyRecord>& ghosts, const HostVector<ShapeRecord>& ghost_shapes);
};

template <class Real>
StepLoop<Real>::StepLoop(Session& session, Engine<Real>& engine, const Frame& frame,
                         const SlabDecomposition& slabs, double width, const StepMotion& motion, int threads)
    : m(std::make_unique<State>(session, engine, frame, slabs, width, motion, threads)) {}

template <class Real>
StepLoop<Real>::~StepLoop() = default;

template <class Real>
StepBodies& StepLoop<Real>::bodies() {
  return m->bodies;
}

template <class Real>
void StepLoop<Real>::lay_out(StepBodies&& bodies) {
  State& s = *m;
  const auto t0 = WallClock::now();
  s.bodies = std::move(bodies);
  // Scenes with ellipsoids: the shape rows go into A and B (the ghosts' with the first exchange).
  // Agreed over the ranks, as a rank without rows has none.
  s.shapes = s.session.sum(std::uint64_t(s.bodies.shapes.empty() ? 0 : 1)) > 0;
  s.refresh = s.shapes && s.motion.refresh_shapes;
  s.grow = s.refresh && s.motion.send_semi_axes;
  const int me = s.session.rank();
  const StepBodies& b = s.bodies;
  Exports<BodyRecord> exports;
  Exports<ShapeRecord> shape_exports;
  agreed_stage(s.session, "steps", [&] {
    std::vector<double> x(b.size());
    for (std::size_t k = 0; k < b.size(); ++k) x[k] = component(b.position[k], s.slabs.axis());
    s.plan = make_step_plan(s.slabs, me, x, s.width, s.threads);
    if (s.plan.owned.size() != b.size()) {
      const std::size_t k = static_cast<std::size_t>(
          std::find(s.plan.role.begin(), s.plan.role.end(), RowRole::ghost) - s.plan.role.begin());
      throw InputError("steps: body " + std::to_string(b.id[k]) + " is not owned by rank " +
                       std::to_string(me));
    }
    s.send_counts = s.plan.halo.counts();
    exports.offsets = s.plan.halo.offsets;
    exports.rows = HostVector<BodyRecord>(s.plan.halo.total());
    if (s.shapes) {
      shape_exports.offsets = s.plan.halo.offsets;
      shape_exports.rows = HostVector<ShapeRecord>(s.plan.halo.total());
    }
    for (std::size_t w = 0; w < s.plan.halo.total(); ++w) {
      const std::size_t k = s.plan.halo.rows[w];
      exports.rows[w] = BodyRecord{b.position[k], b.radius[k], b.id[k]};
      if (s.shapes)
        shape_exports.rows[w] =
            ShapeRecord{b.shapes.orientation[k], b.shapes.semi_axes[k], b.shapes.shape[k]};
    }
    s.a.set_resident(
        BodiesView{b.position, b.radius, {}, {}, b.shapes.shape, b.shapes.semi_axes, b.shapes.orientation});
  });
  s.recv_counts = s.comm.alltoall_counts(s.send_counts);
  // the first exchange carries the ghosts' records (ids too); the steps refresh their rows
  const HostVector<BodyRecord> ghosts = s.comm.exchange(exports.rows, s.send_counts, s.recv_counts);
  HostVector<ShapeRecord> ghost_shapes;  // the same ghosts' shape rows, in the same order
  if (s.shapes) ghost_shapes = s.comm.exchange(shape_exports.rows, s.send_counts, s.recv_counts);
  agreed_stage(s.session, "steps", [&] { s.make_engine_b(ghosts, ghost_shapes); });
  s.halo_rows = ghosts.size();
  s.setup = seconds_since(t0);
}

template <class Real>
void StepLoop<Real>::State::make_engine_b(const HostVector<BodyRecord>& ghosts,
                                          const HostVector<ShapeRecord>& ghost_shapes) {
  pin_p.reset();
  pin_r.reset();
  pin_q.reset();
  b.reset();
  const StepBodies& o = bodies;
  const std::size_t nb = plan.boundary.size();
  std::vector<std::int64_t> boundary_ids(nb), ghost_ids(ghosts.size());
  for (std::size_t k = 0; k < nb; ++k) boundary_ids[k] = o.id[plan.boundary[k]];
  for (std::size_t g = 0; g < ghosts.size(); ++g) ghost_ids[g] = ghosts[g].id;
  rows = merge_boundary_rows(boundary_ids, ghost_ids);
  if (nb == 0) return;  // no boundary row: the ghosts touch none of this rank's bodies
  const std::size_t total = rows.size();
  b_p = HostVector<Vec3<double>>(total);
  b_r = HostVector<double>(total);
  b_id = HostVector<std::int64_t>(total);
  HostVector<std::uint8_t> mask(total);
  ShapeRows b_s;
  if (shapes) {
    b_s.shape = HostVector<Shape>(total);
    b_s.semi_axes = HostVector<Vec3<double>>(total);
    b_s.orientation = HostVector<Quat<double>>(total);
  }
  for (std::size_t k = 0; k < nb; ++k) {
    const std::size_t i = plan.boundary[k], row = rows.of_boundary[k];
    b_p[row] = o.position[i];
    b_r[row] = o.radius[i];
    b_id[row] = o.id[i];
    mask[row] = kReportedBit | kPairedBit;  // A pairs the boundary rows with each other
    if (shapes) {
      b_s.shape[row] = o.shapes.shape[i];
      b_s.semi_axes[row] = o.shapes.semi_axes[i];
      b_s.orientation[row] = o.shapes.orientation[i];
    }
  }
  for (std::size_t g = 0; g < ghosts.size(); ++g) {
    const std::size_t row = rows.of_ghost[g];
    b_p[row] = ghosts[g].position;
    b_r[row] = ghosts[g].radius;
    b_id[row] = ghosts[g].id;
    mask[row] = 0;
    if (shapes) {
      b_s.shape[row] = ghost_shapes[g].shape;
      b_s.semi_axes[row] = ghost_shapes[g].semi_axes;
      b_s.orientation[row] = ghost_shapes[g].orientation;
    }
  }
  b.emplace(a.options());
  b->set_resident(BodiesView{b_p, b_r, {}, mask, b_s.shape, b_s.semi_axes, b_s.orientation});
  pin_p.emplace(a, b_p.data(), b_p.size() * sizeof(Vec3<double>));
  pin_r.emplace(a, b_r.data(), b_r.size() * sizeof(double));
  b_q = {};
  b_semi = {};
  if (refresh) {
    b_q = std::move(b_s.orientation);
    pin_q.emplace(a, b_q.data(), b_q.size() * sizeof(Quat<double>));
  }
  if (grow) b_semi = std::move(b_s.semi_axes);
}

template <class Real>
void StepLoop<Real>::commit(bool positions, bool orientations) {
  State& s = *m;
  StepBodies& b = s.bodies;
  try {
    if (positions) s.a.write_resident(0, b.size(), b.position.data(), b.radius.data());
    if (orientations && !b.shapes.empty())
      s.a.write_resident_shapes(0, b.size(), nullptr, b.shapes.orientation.data());
  } catch (...) {
    s.fail();
  }
}

template <class Real>
void StepLoop<Real>::detect_interior() {
  State& s = *m;
  s.t = {};
  s.found_a = s.found_b = 0;
  s.interior_error = nullptr;
  s.s0 = WallClock::now();
  auto run = [&s] {
    const auto i0 = WallClock::now();
    try {
      s.found_a = s.a.detect_resident(s.frame);
    } catch (...) {
      s.interior_error = std::current_exception();
    }
    s.t[static_cast<std::size_t>(StepStage::interior)] = seconds_since(i0);
  };
  if (s.error) return;
  if (s.session.size() > 1) {
    try {
      s.interior = std::thread(run);  // overlaps the halo
    } catch (...) {
      s.fail();
    }
  } else {
    run();
  }
}

template <class Real>
void StepLoop<Real>::refresh_ghosts() {
  State& s = *m;
  if (s.session.size() == 1) return;
  const auto h0 = WallClock::now();
  const StepBodies& o = s.bodies;
  const auto& halo = s.plan.halo.rows;
  const auto& of_ghost = s.rows.of_ghost;
  // every rank exchanges, whatever its error: its neighbours wait for its messages
  if (s.refresh) {
    HostVector<OrientedRecord> send(halo.size());
    for (std::size_t w = 0; w < halo.size(); ++w)
      send[w] = OrientedRecord{o.position[halo[w]], o.radius[halo[w]], o.shapes.orientation[halo[w]]};
    const HostVector<OrientedRecord> got = s.comm.exchange(send, s.send_counts, s.recv_counts);
    if (s.b)
      for (std::size_t g = 0; g < got.size(); ++g) {
        s.b_p[of_ghost[g]] = got[g].position;
        s.b_r[of_ghost[g]] = got[g].radius;
        s.b_q[of_ghost[g]] = got[g].orientation;
      }
  } else {
    HostVector<BodyRecord> send(halo.size());
    for (std::size_t w = 0; w < halo.size(); ++w)
      send[w] = BodyRecord{o.position[halo[w]], o.radius[halo[w]], 0};
    const HostVector<BodyRecord> got = s.comm.exchange(send, s.send_counts, s.recv_counts);
    if (s.b)
      for (std::size_t g = 0; g < got.size(); ++g) {
        s.b_p[of_ghost[g]] = got[g].position;
        s.b_r[of_ghost[g]] = got[g].radius;
      }
  }
  if (s.grow) {  // semi-axes that grow: a message of their own
    HostVector<Vec3<double>> send(halo.size());
    for (std::size_t w = 0; w < halo.size(); ++w) send[w] = o.shapes.semi_axes[halo[w]];
    const HostVector<Vec3<double>> got = s.comm.exchange(send, s.send_counts, s.recv_counts);
    if (s.b)
      for (std::size_t g = 0; g < got.size(); ++g) s.b_semi[of_ghost[g]] = got[g];
  }
  if (!s.b || s.error) return;
  try {  // the boundary rows as the caller moved them, then B's rows into B
    for (std::size_t k = 0; k < s.plan.boundary.size(); ++k) {
      const std::size_t i = s.plan.boundary[k], row = s.rows.of_boundary[k];
      s.b_p[row] = o.position[i];
      s.b_r[row] = o.radius[i];
      if (s.refresh) s.b_q[row] = o.shapes.orientation[i];
      if (s.grow) s.b_semi[row] = o.shapes.semi_axes[i];
    }
    s.b->write_resident(0, s.b_r.size(), s.b_p.data(), s.b_r.data());
    if (s.refresh)
      s.b->write_resident_shapes(0, s.b_q.size(), s.grow ? s.b_semi.data() : nullptr, s.b_q.data());
  } catch (...) {
    s.fail();
  }
  s.t[static_cast<std::size_t>(StepStage::halo)] = seconds_since(h0);
}

template <class Real>
void StepLoop<Real>::detect_boundary() {
  State& s = *m;
  if (s.b && !s.error) {
    const auto b0 = WallClock::now();
    try {
      s.found_b = s.b->detect_resident(s.frame);
    } catch (...) {
      s.fail();
    }
    s.t[static_cast<std::size_t>(StepStage::boundary)] = seconds_since(b0);
  }
  if (s.interior.joinable()) s.interior.join();
  if (!s.error) s.error = s.interior_error;
  std::exception_ptr error = s.error;
  s.error = nullptr;
  s.session.agree(error, "steps");
  s.t[static_cast<std::size_t>(StepStage::step)] = seconds_since(s.s0);
}

template <class Real>
void StepLoop<Real>::collect() {
  State& s = *m;
  s.found.push_back(s.found_a + s.found_b);
  s.times.push_back(s.t);
  const std::vector<std::string>& names = engine_stage_names();
  std::vector<double> e(names.size(), 0);
  for (const StageTime& t : s.a.times())
    for (std::size_t j = 0; j < names.size(); ++j)
      if (t.name == names[j]) e[j] = t.seconds;
  s.engine_times.push_back(std::move(e));
}

template <class Real>
std::uint64_t StepLoop<Real>::pair_hash_sum() {
  State& s = *m;
  std::uint64_t hash = 0;
  agreed_stage(s.session, "steps", [&] {
    if (s.found.empty()) return;
    auto add = [&](const Contacts<Real>& c, const std::int64_t* ids) {
      for (std::size_t k = 0; k < c.size(); ++k) hash += pair_hash(ids[c.id_a[k]], ids[c.id_b[k]]);
    };
    add(s.a.resident_contacts(), s.bodies.id.data());
    if (s.b) add(s.b->resident_contacts(), s.b_id.data());
  });
  return s.session.sum(hash);
}

template <class Real>
const std::vector<std::uint64_t>& StepLoop<Real>::contacts_per_step() {
  State& s = *m;
  s.found_all = s.found;
  s.comm.allreduce_sum(s.found_all);
  return s.found_all;
}

template <class Real>
StepStats StepLoop<Real>::stats() {
  State& s = *m;
  const std::size_t n = s.times.size(), n_engine = engine_stage_names().size();
  std::vector<double> all;  // per step: the step stages, then engine A's
  for (std::size_t k = 0; k < n; ++k) {
    all.insert(all.end(), s.times[k].begin(), s.times[k].end());
    all.insert(all.end(), s.engine_times[k].begin(), s.engine_times[k].end());
  }
  s.comm.allreduce_max(all);
  const std::size_t row = kStepStageCount + n_engine;
  auto step_median = [&](std::size_t j) {
    std::vector<double> v(n);
    for (std::size_t k = 0; k < n; ++k) v[k] = all[k * row + j];
    return median(std::move(v));
  };
  StepStats st;
  st.steps = static_cast<int>(n);
  st.spin = s.motion.spin;
  st.turned = s.shapes && s.motion.spin != 0;
  st.oriented = s.refresh && s.session.size() > 1;
  st.halo_rows = s.session.sum(s.halo_rows);
  st.setup = s.session.max(s.setup);
  st.halo = step_median(static_cast<std::size_t>(StepStage::halo));
  st.interior = step_median(static_cast<std::size_t>(StepStage::interior));
  st.boundary = step_median(static_cast<std::size_t>(StepStage::boundary));
  st.step = step_median(static_cast<std::size_t>(StepStage::step));
  for (std::size_t j = 0; j < n_engine && n > 0; ++j) {
    const double t = step_median(kStepStageCount + j);
    if (t > 0) st.stages.push_back({engine_stage_names()[j], t});
  }
  return st;
}

template class StepLoop<float>;
template class StepLoop<double>;

}  // namespace cg
