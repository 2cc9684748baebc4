// The bodies of the resident steps and their motion rule (see step_bodies.hpp).
#include "step_bodies.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "errors.hpp"
#include "routing.hpp"
#include "splice_rows.hpp"

namespace cg {

StepBodies sized_step_bodies(std::size_t n, bool shapes, std::size_t state_bytes) {
  StepBodies b;
  b.position = HostVector<Vec3<double>>(n);
  b.radius = HostVector<double>(n);
  b.id = HostVector<std::int64_t>(n);
  if (shapes) {
    b.shapes.shape = HostVector<Shape>(n);
    b.shapes.semi_axes = HostVector<Vec3<double>>(n);
    b.shapes.orientation = HostVector<Quat<double>>(n);
  }
  b.state_bytes = state_bytes;
  b.state = HostVector<std::byte>(n * state_bytes);
  return b;
}

namespace {
// `v` resized to n rows; storage too small is replaced (not grown: the rows are rewritten after, so
// nothing is copied into it), with room for n + n/16 rows (a rank's count changes a little a rebuild).
template <class T>
void resize_discarding(HostVector<T>& v, std::size_t n) {
  if (n > v.capacity()) {
    HostVector<T> fresh;
    fresh.reserve(n + n / 16);
    v.swap(fresh);
  }
  v.resize(n);
}
}  // namespace

void resize_step_bodies(StepBodies& b, std::size_t n, bool shapes, std::size_t state_bytes) {
  resize_discarding(b.position, n);
  resize_discarding(b.radius, n);
  resize_discarding(b.id, n);
  resize_discarding(b.shapes.shape, shapes ? n : 0);
  resize_discarding(b.shapes.semi_axes, shapes ? n : 0);
  resize_discarding(b.shapes.orientation, shapes ? n : 0);
  b.state_bytes = state_bytes;
  resize_discarding(b.state, n * state_bytes);
}

std::vector<std::size_t> arrival_places(const StepBodies& from, std::span<const std::size_t> leaving,
                                        const StepBodies& arrivals, bool shapes, int threads) {
  const std::size_t n = from.size(), m = arrivals.size(), stride = from.state_bytes;
  if (m > 0 && arrivals.state_bytes != stride)
    throw Error("migration: the arrivals carry other state than the rows: internal error");
  if ((shapes && ((n > 0 && from.shapes.empty()) || (m > 0 && arrivals.shapes.empty()))) ||
      (!shapes && (!from.shapes.empty() || !arrivals.shapes.empty())))
    throw Error("migration: shape rows on one side only: internal error");
  for (std::size_t j = 1; j < m; ++j)
    if (!(arrivals.id[j - 1] < arrivals.id[j]))
      throw Error("migration: body " + std::to_string(arrivals.id[j]) + " arrives twice: internal error");
  // Where each arrival goes: before the first row of `from` with a larger id (a row that stays with
  // its id: the body would be held twice). One search a row over every id (a cache miss a level
  // below the shared top of the searches), so in parallel; then the first arrival held twice.
  std::vector<std::size_t> before(m);
  const int team = std::max(1, threads);
#pragma omp parallel for num_threads(team) schedule(static) if (m > 256)
  for (std::size_t j = 0; j < m; ++j)
    before[j] = static_cast<std::size_t>(std::lower_bound(from.id.begin(), from.id.end(), arrivals.id[j]) -
                                         from.id.begin());
  const std::size_t bad = first_bad(m, team, [&](std::size_t j) {
    const std::size_t p = before[j];
    return p < n && from.id[p] == arrivals.id[j] && !std::binary_search(leaving.begin(), leaving.end(), p);
  });
  if (bad < m)
    throw Error("steps: body " + std::to_string(arrivals.id[bad]) +
                " is held twice after migration: internal error");
  plan_splice(n, leaving, before, "migration (internal error)");
  return before;
}

void splice_step_bodies(const StepBodies& from, std::span<const std::size_t> leaving,
                        std::span<const std::size_t> before, const StepBodies& arrivals, bool shapes,
                        StepBodies& into, int threads) {
  const std::size_t stride = from.state_bytes;
  const SplicePlan plan = plan_splice(from.size(), leaving, before, "migration (internal error)");
  resize_step_bodies(into, plan.size, shapes, stride);
  splice_rows(plan, from.position.data(), arrivals.position.data(), into.position.data(), 1, threads);
  splice_rows(plan, from.radius.data(), arrivals.radius.data(), into.radius.data(), 1, threads);
  splice_rows(plan, from.id.data(), arrivals.id.data(), into.id.data(), 1, threads);
  if (shapes) {
    splice_rows(plan, from.shapes.shape.data(), arrivals.shapes.shape.data(), into.shapes.shape.data(), 1,
                threads);
    splice_rows(plan, from.shapes.semi_axes.data(), arrivals.shapes.semi_axes.data(),
                into.shapes.semi_axes.data(), 1, threads);
    splice_rows(plan, from.shapes.orientation.data(), arrivals.shapes.orientation.data(),
                into.shapes.orientation.data(), 1, threads);
  }
  if (stride > 0)
    splice_rows(plan, from.state.data(), arrivals.state.data(), into.state.data(), stride, threads);
}

std::vector<std::size_t> merge_step_bodies(const StepBodies& from, std::span<const std::size_t> leaving,
                                           const StepBodies& arrivals, bool shapes, StepBodies& into,
                                           int threads) {
  std::vector<std::size_t> before = arrival_places(from, leaving, arrivals, shapes, threads);
  splice_step_bodies(from, leaving, before, arrivals, shapes, into, threads);
  return before;
}

SpliceMap::SpliceMap(std::size_t n, std::span<const std::size_t> leaving, std::span<const std::size_t> before)
    : m_size(n - leaving.size() + before.size()), m_arrival_row(before.size()), m_gap(leaving.size()) {
  // arrival j goes before old row before[j], after the arrivals before it (splice_rows.hpp's rule)
  for (std::size_t j = 0; j < before.size(); ++j) {
    const auto gone = static_cast<std::size_t>(std::lower_bound(leaving.begin(), leaving.end(), before[j]) -
                                               leaving.begin());
    m_arrival_row[j] = before[j] - gone + j;
  }
  for (std::size_t j = 0; j < leaving.size(); ++j) m_gap[j] = leaving[j] - j;
  // each bucket's first arrival row at or above its first row, and first gap above it
  const std::size_t buckets = (m_size >> k_bucket_bits) + 2;  // (a bucket's end is the next's first)
  m_arrival_from.resize(buckets);
  m_gap_from.resize(buckets);
  for (std::size_t b = 0, a = 0, g = 0; b < buckets; ++b) {
    const std::size_t row = b << k_bucket_bits;
    while (a < m_arrival_row.size() && m_arrival_row[a] < row) ++a;
    while (g < m_gap.size() && m_gap[g] < row) ++g;
    m_arrival_from[b] = a;
    m_gap_from[b] = g;
  }
}

SpliceMap::Source SpliceMap::operator()(std::size_t i) const {
  // the arrivals before row i: searched within its bucket's (a few entries where the changes spread)
  const std::size_t bi = i >> k_bucket_bits;
  const auto arrivals = m_arrival_row.begin();
  const auto a = static_cast<std::size_t>(
      std::lower_bound(arrivals + static_cast<std::ptrdiff_t>(m_arrival_from[bi]),
                       arrivals + static_cast<std::ptrdiff_t>(m_arrival_from[bi + 1]), i) -
      arrivals);
  if (a < m_arrival_row.size() && m_arrival_row[a] == i) return {true, a};
  // the s-th row that stays: old row s + j, j the leaving rows before it (the first j with
  // leaving[j] - j > s), searched within s's bucket's
  const std::size_t s = i - a, bs = s >> k_bucket_bits;
  const auto gaps = m_gap.begin();
  const auto j =
      static_cast<std::size_t>(std::upper_bound(gaps + static_cast<std::ptrdiff_t>(m_gap_from[bs]),
                                                gaps + static_cast<std::ptrdiff_t>(m_gap_from[bs + 1]), s) -
                               gaps);
  return {false, s + j};
}

StepBodies owned_bodies(const EngineInput& in, int threads) {
  const std::size_t n = in.radius.size();
  std::vector<std::size_t> rows;
  rows.reserve(static_cast<std::size_t>(in.owned));
  for (std::size_t i = 0; i < n; ++i)
    if (in.implied() || (in.report[i] & kReportedBit)) rows.push_back(i);  // owned (ghosts may be wide)
  const bool shapes = !in.shapes.empty();
  const std::size_t m = rows.size();
  StepBodies b = sized_step_bodies(m, shapes);
#pragma omp parallel for num_threads(threads) schedule(static)
  for (std::size_t k = 0; k < m; ++k) {
    const std::size_t i = rows[k];
    b.position[k] = in.position[i];
    b.radius[k] = in.radius[i];
    b.id[k] = in.implied() ? static_cast<std::int64_t>(i) : in.id[i];
    if (shapes) {
      b.shapes.shape[k] = in.shapes.shape[i];
      b.shapes.semi_axes[k] = in.shapes.semi_axes[i];
      b.shapes.orientation[k] = in.shapes.orientation[i];
    }
  }
  return b;
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

namespace {
// A unit vector uniform on the sphere from the id and two hash keys (z uniform in [-1, 1), the
// azimuth uniform).
Vec3<double> unit_from_id(std::int64_t id, std::int64_t key_z, std::int64_t key_phi) {
  constexpr double k_unit = 0x1.0p-53;  // 53 random bits → [0, 1)
  const double z = 2 * static_cast<double>(pair_hash(id, key_z) >> 11) * k_unit - 1;
  const double phi = 2 * std::numbers::pi * static_cast<double>(pair_hash(id, key_phi) >> 11) * k_unit;
  const double s = std::sqrt(std::max(0.0, 1 - z * z));
  return {s * std::cos(phi), s * std::sin(phi), z};
}
}  // namespace

Vec3<double> spin_axis(std::int64_t id) { return unit_from_id(id, 1, 2); }

Vec3<double> drift_direction(std::int64_t id) { return unit_from_id(id, 3, 4); }

Vec3<double> drifted_position(std::int64_t id, Vec3<double> c0, double drift, int step) {
  const Vec3<double> u = drift_direction(id);
  const double d = drift * step;
  return {c0.x + u.x * d, c0.y + u.y * d, c0.z + u.z * d};
}

template <class Real>
std::uint64_t contacts_hash(const Contacts<Real>& c) {
  std::uint64_t sum = 0;
  for (std::size_t k = 0; k < c.size(); ++k) {
    std::uint64_t h = pair_hash(c.id_a[k], c.id_b[k]);
    auto mix = [&h](Real v) {
      std::uint64_t bits = 0;
      std::memcpy(&bits, &v, sizeof(Real));
      h = pair_hash(static_cast<std::int64_t>(h), static_cast<std::int64_t>(bits));
    };
    for_each_contact_field(c, c.full, [&](auto index, const auto& column) {
      if constexpr (kContactFields[decltype(index)::value].kind == FieldKind::vector) {
        mix(column[k].x);
        mix(column[k].y);
        mix(column[k].z);
      } else if constexpr (kContactFields[decltype(index)::value].kind == FieldKind::scalar) {
        mix(column[k]);
      }
    });
    sum += h;
  }
  return sum;
}
template std::uint64_t contacts_hash(const Contacts<float>&);
template std::uint64_t contacts_hash(const Contacts<double>&);

namespace {
// a ⊗ b: the rotation b, then a.
Quat<double> product(const Quat<double>& a, const Quat<double>& b) {
  return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
          a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}

// Row k's pose: a FilePose, or in a scene of spheres alone its centre (the identity orientation).
FilePose pose_of(const StepBodies& b, std::size_t k) {
  FilePose p{{}, {1, 0, 0, 0}};
  if (b.state_bytes == sizeof(FilePose))
    std::memcpy(&p, b.state.data() + k * sizeof(FilePose), sizeof(FilePose));
  else
    std::memcpy(&p.position, b.state.data() + k * sizeof(Vec3<double>), sizeof(Vec3<double>));
  return p;
}
}  // namespace

Quat<double> spun_orientation(std::int64_t id, Quat<double> q0, double angle) {
  const Vec3<double> a = spin_axis(id);
  const double c = std::cos(angle / 2), s = std::sin(angle / 2);
  return product({c, s * a.x, s * a.y, s * a.z}, q0);
}

void attach_file_poses(StepBodies& b, bool orientations, int threads) {
  const std::size_t n = b.size();
  const bool shapes = !b.shapes.empty();  // (else spheres alone: the identity where orientations)
  b.state_bytes = file_pose_bytes(orientations);
  b.state = HostVector<std::byte>(n * b.state_bytes);
#pragma omp parallel for num_threads(threads) schedule(static)
  for (std::size_t k = 0; k < n; ++k) {
    if (!orientations) {
      std::memcpy(b.state.data() + k * sizeof(Vec3<double>), &b.position[k], sizeof(Vec3<double>));
      continue;
    }
    const FilePose p{b.position[k], shapes ? b.shapes.orientation[k] : Quat<double>{1, 0, 0, 0}};
    std::memcpy(b.state.data() + k * sizeof(FilePose), &p, sizeof(FilePose));
  }
}

Moved move_bodies(StepBodies& b, const StepMotion& motion, int step, int threads) {
  Moved moved;
  moved.positions = motion.drift != 0;
  moved.orientations = motion.spin != 0 && !b.shapes.empty();
  if (b.state_bytes != file_pose_bytes(true) &&
      (b.state_bytes != file_pose_bytes(false) || moved.orientations))
    throw Error("move_bodies: the bodies carry no file pose: internal error");
  if (!moved.positions && !moved.orientations) return moved;
  const double angle = motion.spin * step;
  const std::size_t n = b.size();
#pragma omp parallel for num_threads(threads) schedule(static)
  for (std::size_t k = 0; k < n; ++k) {
    const FilePose pose = pose_of(b, k);
    if (moved.positions) b.position[k] = drifted_position(b.id[k], pose.position, motion.drift, step);
    if (moved.orientations && b.shapes.shape[k] == Shape::ellipsoid)
      b.shapes.orientation[k] = spun_orientation(b.id[k], pose.orientation, angle);
  }
  return moved;
}

}  // namespace cg
