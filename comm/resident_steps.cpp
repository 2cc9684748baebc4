// Resident steps (see resident_steps.hpp): layout, first exchange, then the timed steps.
#include "resident_steps.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <optional>
#include <thread>

#include "agreed_stage.hpp"
#include "stage.hpp"  // the engine's typed stage names
#include "transport.hpp"

namespace cg {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// One rank's rows for the steps and where its halo ranges lie.
struct StepLayout {
  std::vector<std::uint64_t> send_counts, recv_counts;  // per rank, fixed for every step
  std::size_t owned = 0;         // owned rows: [down only][both ways][up only][interior] (engine A)
  std::size_t down = 0, up = 0;  // owned rows sent to lower ranks: the first `down`; up: [sent - up, sent)
  std::size_t sent = 0;          // owned rows sent anywhere: the first `sent` (the boundary)
  std::size_t lower_ghosts = 0;  // boundary rows (engine B): [lower ghosts][the `sent` owned][upper ghosts]
};

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

// Shape rows for `n` bodies (0: none, all spheres) and row k set from a ShapeRecord.
ShapeRows shaped_rows(std::size_t n) {
  ShapeRows s;
  s.shape = HostVector<Shape>(n);
  s.semi_axes = HostVector<Vec3<double>>(n);
  s.orientation = HostVector<Quat<double>>(n);
  return s;
}
void put(ShapeRows& s, std::size_t k, const ShapeRecord& r) {
  s.shape[k] = r.shape;
  s.semi_axes[k] = r.semi_axes;
  s.orientation[k] = r.orientation;
}

// B's boundary rows [lower_ghosts, lower_ghosts + sent) in the order the halo sends them (per
// destination rank: the downward set to a lower rank, the upward set to a higher one): f(w, j) puts
// B's row j at send position w.
template <class F>
void for_each_sent(const StepLayout& l, int me, F&& f) {
  std::size_t w = 0;
  for (std::size_t q = 0; q < l.send_counts.size(); ++q) {
    const std::size_t from = l.lower_ghosts + (static_cast<int>(q) < me ? 0 : l.sent - l.up);
    for (std::size_t j = from; j < from + l.send_counts[q]; ++j) f(w++, j);
  }
}

// B's row of the g-th received ghost: the lower ranks' before the boundary owned rows, the upper
// ranks' after them.
std::size_t ghost_row(const StepLayout& l, std::size_t g) { return g < l.lower_ghosts ? g : g + l.sent; }

// A boundary row as a step sends it in a scene with ellipsoids: the orientation in the same message
// as the position and bounding radius (64 bytes; a sphere-only scene sends BodyRecords, 40).
struct OrientedRecord {
  Vec3<double> position;
  double radius;
  Quat<double> orientation;
};

// One message per neighbour of B's rows: `record(j)` of each boundary row j goes out as the layout
// says (through `send`), and `put(row, r)` lands each received record in B's ghost row. Every rank
// calls it (whatever its error: its neighbours wait for its messages).
template <class R, class Record, class Put>
void halo_rows(const detail::Comm& comm, const StepLayout& l, int me, HostVector<R>& send, Record&& record,
               Put&& put) {
  for_each_sent(l, me, [&](std::size_t w, std::size_t j) { send[w] = record(j); });
  const HostVector<R> got = comm.exchange(send, l.send_counts, l.recv_counts);
  for (std::size_t g = 0; g < got.size(); ++g) put(ghost_row(l, g), got[g]);
}

// a ⊗ b: the rotation b, then a.
Quat<double> product(const Quat<double>& a, const Quat<double>& b) {
  return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
          a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}

double median_of(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

}  // namespace

const std::vector<std::string>& engine_stage_names() {
  static const std::vector<std::string> names = [] {  // the engine's typed stages (stage.hpp)
    std::vector<std::string> v;
    for (int i = 0; i < detail::kStageCount; ++i) v.emplace_back(detail::name(detail::stage_at(i)));
    return v;
  }();
  return names;
}

// An order-free fingerprint of a contact set: the sum over its pairs (splitmix64 of the two ids).
std::uint64_t pair_hash(std::int64_t a, std::int64_t b) {
  std::uint64_t x = static_cast<std::uint64_t>(a) * 0x9E3779B97F4A7C15ull ^ static_cast<std::uint64_t>(b);
  x ^= x >> 30;
  x *= 0xBF58476D1CE4E5B9ull;
  x ^= x >> 27;
  x *= 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

Vec3<double> spin_axis(std::int64_t id) {
  constexpr double k_unit = 0x1.0p-53;  // 53 random bits → [0, 1)
  const double z = 2 * static_cast<double>(pair_hash(id, 1) >> 11) * k_unit - 1;
  const double phi = 2 * std::numbers::pi * static_cast<double>(pair_hash(id, 2) >> 11) * k_unit;
  const double s = std::sqrt(std::max(0.0, 1 - z * z));
  return {s * std::cos(phi), s * std::sin(phi), z};
}

Quat<double> spun_orientation(std::int64_t id, Quat<double> q0, double angle) {
  const Vec3<double> a = spin_axis(id);
  const double c = std::cos(angle / 2), s = std::sin(angle / 2);
  return product({c, s * a.x, s * a.y, s * a.z}, q0);
}

template <class Real>
StepStats resident_steps(Session& session, Engine<Real>& engine, const Frame& frame,
                         const SlabDecomposition& slab_decomposition, double width, const EngineInput& in,
                         int steps, const StepMotion& motion, std::uint64_t expected,
                         std::uint64_t expected_hash, int threads) {
  const detail::Comm comm(session);
  // One rank has no neighbours: no halo, no engine B; every row resident as held, all pairs.
  const SlabDecomposition* slabs = session.size() > 1 ? &slab_decomposition : nullptr;
  const int axis = slab_decomposition.axis();
  const std::span<const Vec3<double>> position = in.position;
  const std::span<const double> radius = in.radius;
  const std::span<const std::int64_t> id = in.id;
  const std::span<const std::uint8_t> report = in.report;
  auto id_of = [&](std::size_t i) { return in.implied() ? static_cast<std::int64_t>(i) : id[i]; };
  // Scenes with ellipsoids: the shape rows go with the bodies into A and B (the ghosts' with the first
  // exchange), and every step refreshes B's orientations (semi-axes too when they grow) as it does
  // the positions. Agreed over the ranks, as a rank without rows has none.
  const bool shapes = session.sum(std::uint64_t(in.shapes.empty() ? 0 : 1)) > 0;
  const bool refresh = shapes && motion.refresh_shapes, grow = motion.send_semi_axes;
  const ShapeRows& shape_rows = in.shapes;
  auto shape_of = [&](std::size_t i) {
    return ShapeRecord{shape_rows.orientation[i], shape_rows.semi_axes[i], shape_rows.shape[i]};
  };
  // Input row i's orientation at `angle` by the spin's rule (spheres keep theirs).
  auto turned = [&](std::size_t i, double angle) {
    return shape_rows.shape[i] == Shape::ellipsoid
               ? spun_orientation(id_of(i), shape_rows.orientation[i], angle)
               : shape_rows.orientation[i];
  };
  StepStats st;
  st.steps = steps;
  st.spin = motion.spin;
  st.turned = shapes && motion.spin != 0;
  st.oriented = refresh && session.size() > 1;
  const int ranks = session.size(), me = session.rank();
  const std::size_t p = static_cast<std::size_t>(ranks), n = radius.size(),
                    n_steps = static_cast<std::size_t>(steps);
  const auto t0 = Clock::now();
  StepLayout l;
  l.send_counts.assign(p, 0);
  l.recv_counts.assign(p, 0);
  HostVector<std::int64_t> owned_id;    // engine A's rows → global id
  std::vector<std::size_t> owned_rows;  // engine A's rows → input rows (one rank: the same rows)
  HostVector<Vec3<double>> b_p;         // engine B's rows, host side (page-locked)
  HostVector<double> b_r;
  HostVector<std::int64_t> b_id;
  HostVector<Quat<double>> b_q;          // B's orientations (scenes with ellipsoids)
  HostVector<Vec3<double>> b_semi;       // B's semi-axes (when they travel: StepMotion::send_semi_axes)
  std::optional<Engine<Real>> boundary;  // engine B
  std::optional<Pin<Real>> pin_p, pin_r, pin_q;
  if (!slabs) {  // one rank: every row resident as held (all owned, in id order: ids implied), all pairs
    agreed_stage(session, "steps", [&] {
      engine.set_resident(BodiesView{
          position, radius, {}, {}, shape_rows.shape, shape_rows.semi_axes, shape_rows.orientation});
    });
  } else {
    agreed_stage(session, "steps", [&] {
      HostVector<std::uint8_t> cls(n);
      std::vector<char> need(p, 0);
#pragma omp parallel num_threads(threads)
      {
        std::vector<char> mine(p, 0);
#pragma omp for schedule(static)
        for (std::size_t i = 0; i < n; ++i) {
          if (!in.implied() && !(report[i] & kReportedBit)) {
            cls[i] = 4;  // a ghost of the file run
            continue;
          }
          bool down = false, up = false;
          slabs->for_each_ghost_rank(component(position[i], axis), width, [&](int q) {
            mine[static_cast<std::size_t>(q)] = 1;
            (q < me ? down : up) = true;
          });
          cls[i] = down && up ? 1 : down ? 0 : up ? 2 : 3;
        }
#pragma omp critical
        for (std::size_t q = 0; q < p; ++q) need[q] |= mine[q];
      }
      std::size_t count[5] = {0, 0, 0, 0, 0};
      for (std::size_t i = 0; i < n; ++i) ++count[cls[i]];
      std::size_t at[4] = {0, count[0], count[0] + count[1], count[0] + count[1] + count[2]};
      owned_rows.resize(at[3] + count[3]);
      for (std::size_t i = 0; i < n; ++i)
        if (cls[i] < 4) owned_rows[at[cls[i]]++] = i;
      l.owned = owned_rows.size();
      l.down = count[0] + count[1];
      l.up = count[1] + count[2];
      l.sent = count[0] + count[1] + count[2];
      for (std::size_t q = 0; q < p; ++q)
        if (need[q]) l.send_counts[q] = static_cast<int>(q) < me ? l.down : l.up;
      // engine A: the owned rows, all their pairs
      HostVector<Vec3<double>> a_p(l.owned);
      HostVector<double> a_r(l.owned);
      ShapeRows a_s = shaped_rows(shapes ? l.owned : 0);
      owned_id = HostVector<std::int64_t>(l.owned);
#pragma omp parallel for num_threads(threads) schedule(static)
      for (std::size_t k = 0; k < l.owned; ++k) {
        a_p[k] = position[owned_rows[k]];
        a_r[k] = radius[owned_rows[k]];
        owned_id[k] = id_of(owned_rows[k]);
        if (shapes) put(a_s, k, shape_of(owned_rows[k]));
      }
      engine.set_resident(BodiesView{a_p, a_r, {}, {}, a_s.shape, a_s.semi_axes, a_s.orientation});
    });
    l.recv_counts = comm.alltoall_counts(l.send_counts);
    for (std::size_t q = 0; q < static_cast<std::size_t>(me); ++q) l.lower_ghosts += l.recv_counts[q];
    // the first exchange carries the ghosts' records (ids too); later steps refresh their rows
    HostVector<BodyRecord> send;
    HostVector<ShapeRecord> send_shapes;
    agreed_stage(session, "steps", [&] {
      std::uint64_t total = 0;
      for (std::uint64_t c : l.send_counts) total += c;
      send = HostVector<BodyRecord>(total);
      if (shapes) send_shapes = HostVector<ShapeRecord>(total);
      std::size_t w = 0;
      for (std::size_t q = 0; q < p; ++q) {
        const std::size_t from = static_cast<int>(q) < me ? 0 : l.sent - l.up;
        for (std::size_t k = from; k < from + l.send_counts[q]; ++k) {
          const std::size_t i = owned_rows[k];
          if (shapes) send_shapes[w] = shape_of(i);
          send[w++] = BodyRecord{position[i], radius[i], id_of(i)};
        }
      }
    });
    const HostVector<BodyRecord> got = comm.exchange(send, l.send_counts, l.recv_counts);
    HostVector<ShapeRecord> got_shapes;  // the same ghosts' shape rows, in the same order
    if (shapes) got_shapes = comm.exchange(send_shapes, l.send_counts, l.recv_counts);
    agreed_stage(session, "steps", [&] {
      // engine B: [lower ghosts][boundary owned rows][upper ghosts]; the owned ones are paired with
      // each other by engine A already
      const std::size_t total = l.sent + got.size();
      b_p = HostVector<Vec3<double>>(total);
      b_r = HostVector<double>(total);
      b_id = HostVector<std::int64_t>(total);
      HostVector<std::uint8_t> mask(total);
      ShapeRows b_s = shaped_rows(shapes ? total : 0);
      for (std::size_t k = 0; k < total; ++k) {
        const bool ghost = k < l.lower_ghosts || k >= l.lower_ghosts + l.sent;
        if (ghost) {
          const std::size_t g_at = k < l.lower_ghosts ? k : k - l.sent;
          const BodyRecord& g = got[g_at];
          b_p[k] = g.position;
          b_r[k] = g.radius;
          b_id[k] = g.id;
          if (shapes) put(b_s, k, got_shapes[g_at]);
        } else {
          const std::size_t i = owned_rows[k - l.lower_ghosts];
          b_p[k] = position[i];
          b_r[k] = radius[i];
          b_id[k] = id_of(i);
          if (shapes) put(b_s, k, shape_of(i));
        }
        mask[k] = ghost ? 0 : kReportedBit | kPairedBit;
      }
      boundary.emplace(engine.options());
      boundary->set_resident(BodiesView{b_p, b_r, {}, mask, b_s.shape, b_s.semi_axes, b_s.orientation});
      pin_p.emplace(engine, b_p.data(), b_p.size() * sizeof(Vec3<double>));
      pin_r.emplace(engine, b_r.data(), b_r.size() * sizeof(double));
      if (refresh) {
        b_q = std::move(b_s.orientation);
        pin_q.emplace(engine, b_q.data(), b_q.size() * sizeof(Quat<double>));
      }
      if (refresh && grow) b_semi = std::move(b_s.semi_axes);
    });
    st.halo_rows = got.size();
  }
  st.setup = session.max(seconds_since(t0));
  st.halo_rows = session.sum(st.halo_rows);

  // Each step: the boundary owned rows out of engine A; A detects its owned rows (another thread)
  // while this thread exchanges the halo (MPI only here) and writes engine B's rows, then B detects.
  // Per step (max over ranks): halo, interior (A), boundary (B), step (wall); medians reported.
  // With a spin, the owners first write their ellipsoids' orientations of the step into A (the
  // integrator's part, before the step's clock).
  std::uint64_t total_send = 0;
  for (std::uint64_t c : l.send_counts) total_send += c;
  HostVector<BodyRecord> send(refresh ? 0 : total_send);
  HostVector<OrientedRecord> send_oriented(refresh ? total_send : 0);
  HostVector<Vec3<double>> send_semi(refresh && grow ? total_send : 0);
  HostVector<Quat<double>> a_q(st.turned ? (slabs ? l.owned : n) : 0);  // A's orientations of a step
  const std::size_t n_stages = engine_stage_names().size();
  std::vector<double> times(4 * n_steps, 0), stage_times(n_stages * n_steps, 0);
  std::vector<std::uint64_t> found(n_steps, 0);
  const std::size_t mid = l.lower_ghosts;  // B's boundary owned rows start here
  auto turn_owned = [&](double angle) {    // A's rows at the step's angle (its owned ellipsoids turn)
#pragma omp parallel for num_threads(threads) schedule(static)
    for (std::size_t r = 0; r < a_q.size(); ++r) a_q[r] = turned(slabs ? owned_rows[r] : r, angle);
    engine.write_resident_shapes(0, a_q.size(), nullptr, a_q.data());
  };
  for (std::size_t k = 0; k < n_steps; ++k) {
    std::exception_ptr error, interior_error;
    Clock::time_point s0;
    std::uint64_t found_a = 0, found_b = 0;
    double t_interior = 0;
    std::thread interior;
    auto detect_interior = [&] {
      const auto i0 = Clock::now();
      try {
        found_a = engine.detect_resident(frame);
      } catch (...) {
        interior_error = std::current_exception();
      }
      t_interior = seconds_since(i0);
    };
    try {
      if (st.turned) turn_owned(motion.spin * static_cast<double>(k + 1));  // before the step's clock
      s0 = Clock::now();
      if (slabs) {
        engine.read_resident(0, l.sent, b_p.data() + mid, b_r.data() + mid);
        if (refresh)
          engine.read_resident_shapes(0, l.sent, grow ? b_semi.data() + mid : nullptr, b_q.data() + mid);
        interior = std::thread(detect_interior);
      } else {
        detect_interior();
      }
    } catch (...) {
      error = std::current_exception();
    }
    double t_halo = 0, t_boundary = 0;
    if (slabs) {  // every rank exchanges, whatever its error
      if (refresh) {
        halo_rows(
            comm, l, me, send_oriented,
            [&](std::size_t j) {
              return OrientedRecord{b_p[j], b_r[j], b_q[j]};
            },
            [&](std::size_t row, const OrientedRecord& g) {
              b_p[row] = g.position;
              b_r[row] = g.radius;
              b_q[row] = g.orientation;
            });
      } else {
        halo_rows(
            comm, l, me, send,
            [&](std::size_t j) {
              return BodyRecord{b_p[j], b_r[j], 0};
            },
            [&](std::size_t row, const BodyRecord& g) {
              b_p[row] = g.position;
              b_r[row] = g.radius;
            });
      }
      if (refresh && grow) {  // semi-axes that grow: a message of their own
        halo_rows(
            comm, l, me, send_semi, [&](std::size_t j) { return b_semi[j]; },
            [&](std::size_t row, const Vec3<double>& v) { b_semi[row] = v; });
      }
      try {
        if (!error) {
          boundary->write_resident(0, b_r.size(), b_p.data(), b_r.data());
          if (refresh)
            boundary->write_resident_shapes(0, b_q.size(), grow ? b_semi.data() : nullptr, b_q.data());
          t_halo = seconds_since(s0);
          const auto b0 = Clock::now();
          found_b = boundary->detect_resident(frame);
          t_boundary = seconds_since(b0);
        }
      } catch (...) {
        if (!error) error = std::current_exception();
      }
    }
    if (interior.joinable()) interior.join();
    if (!error) error = interior_error;
    session.agree(error, "steps");
    times[4 * k] = t_halo;
    times[4 * k + 1] = t_interior;
    times[4 * k + 2] = t_boundary;
    times[4 * k + 3] = seconds_since(s0);
    found[k] = found_a + found_b;
    for (const StageTime& t : engine.times())
      for (std::size_t j = 0; j < n_stages; ++j)
        if (t.name == engine_stage_names()[j]) stage_times[k * n_stages + j] = t.seconds;
  }
  comm.allreduce_max(times);
  comm.allreduce_max(stage_times);

  // The pairs of the last step (as global ids; CUDA: downloaded now, after the timing) hash to the
  // run's (an order-free sum), so a missed pair and a duplicate cannot cancel out in the count.
  std::uint64_t hash = 0;
  if (steps > 0) {
    auto add = [&](const Contacts<Real>& c, const std::int64_t* ids) {
      for (std::size_t k = 0; k < c.size(); ++k) {
        const std::int64_t a = ids ? ids[c.id_a[k]] : c.id_a[k], b = ids ? ids[c.id_b[k]] : c.id_b[k];
        hash += pair_hash(std::min(a, b), std::max(a, b));
      }
    };
    add(engine.resident_contacts(), slabs ? owned_id.data() : nullptr);
    if (boundary) add(boundary->resident_contacts(), b_id.data());
  }
  st.hash = session.sum(hash);
  if (st.turned && steps > 0) {  // the last step against the turned bodies detected from scratch
    st.contacts = session.sum(found[n_steps - 1]);
    boundary.reset();  // B is done: its memory for the engine from scratch
    std::uint64_t want = 0, want_hash = 0;
    agreed_stage(session, "steps", [&] {
      if (in.owned == 0) return;  // as the file run: a rank without owned bodies detects nothing
      HostVector<Quat<double>> q(n);
#pragma omp parallel for num_threads(threads) schedule(static)
      for (std::size_t i = 0; i < n; ++i) q[i] = turned(i, motion.spin * static_cast<double>(steps));
      EngineOptions options = engine.options();
      options.skin = 0;
      BodiesView bodies = in.view();
      bodies.orientation = q;
      const Contacts<Real> c = Engine<Real>(options).detect(bodies, frame);
      want = c.size();
      for (std::size_t j = 0; j < c.size(); ++j)
        want_hash += pair_hash(std::min(c.id_a[j], c.id_b[j]), std::max(c.id_a[j], c.id_b[j]));
    });
    want = session.sum(want);
    want_hash = session.sum(want_hash);
    agreed_stage(session, "steps", [&] {
      if ((st.contacts != want || st.hash != want_hash) && me == 0)
        throw Error("resident steps: the last step's " + std::to_string(st.contacts) +
                    " contacts over the ranks differ from a detection of the turned bodies from scratch (" +
                    std::to_string(want) + (st.contacts == want ? ", other pairs" : "") +
                    "): a stale orientation; internal error");
    });
  }
  for (std::size_t k = 0; k < n_steps && !st.turned; ++k) {
    st.contacts = session.sum(found[k]);
    agreed_stage(session, "steps", [&] {
      if (st.contacts != expected && me == 0)
        throw Error("resident step " + std::to_string(k) + ": " + std::to_string(st.contacts) +
                    " contacts over the ranks, the run found " + std::to_string(expected) +
                    ": internal error");
      if (k + 1 == n_steps && st.hash != expected_hash && me == 0)
        throw Error("resident steps: the last step's pairs differ from the run's: internal error");
    });
  }
  std::vector<double> v[4];
  for (std::size_t k = 0; k < n_steps; ++k)
    for (int j = 0; j < 4; ++j) v[j].push_back(times[4 * k + static_cast<std::size_t>(j)]);
  st.halo = median_of(v[0]);
  st.interior = median_of(v[1]);
  st.boundary = median_of(v[2]);
  st.step = median_of(v[3]);
  for (std::size_t j = 0; j < n_stages && steps > 0; ++j) {
    std::vector<double> w;
    for (std::size_t k = 0; k < n_steps; ++k) w.push_back(stage_times[k * n_stages + j]);
    const double m = median_of(w);
    if (m > 0) st.stages.push_back({engine_stage_names()[j], m});
  }
  return st;
}

template StepStats resident_steps(Session&, Engine<float>&, const Frame&, const SlabDecomposition&, double,
                                  const EngineInput&, int, const StepMotion&, std::uint64_t, std::uint64_t,
                                  int);
template StepStats resident_steps(Session&, Engine<double>&, const Frame&, const SlabDecomposition&, double,
                                  const EngineInput&, int, const StepMotion&, std::uint64_t, std::uint64_t,
                                  int);

}  // namespace cg
