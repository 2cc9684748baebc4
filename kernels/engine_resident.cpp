// The engine's resident bodies (Engine::set_resident and the calls on them: reads, writes, splices,
// marks, their detection) and the row lists a step loop moves between engines (set_row_list,
// gather_rows, scatter_rows, copy_rows, rows_outside): the CPU backend's rows here, the CUDA backend's
// on the device (backend.hpp).
#include <omp.h>

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "engine_impl.hpp"
#include "resident_rows.hpp"
#include "splice_rows.hpp"

namespace cg {

namespace {
// UsageError naming `what` unless every array of `b` given has `rows` rows (position always; report and
// id when given; the three shape arrays together or none).
void check_resident_lengths(const BodiesView& b, std::size_t rows, const char* what) {
  const std::size_t m = b.size();
  const bool shapes = !b.shape.empty();
  if (b.position.size() != m || rows != m || (!b.report.empty() && b.report.size() != m) ||
      (!b.id.empty() && b.id.size() != m) ||
      (shapes && (b.shape.size() != m || b.semi_axes.size() != m || b.orientation.size() != m)) ||
      (!shapes && (!b.semi_axes.empty() || !b.orientation.empty())))
    throw UsageError(std::string(what) + ": the arrays differ in length");
}

// The resident rows are now `rows` other rows: what was known of the former ones is dropped (the
// rebuild check's mark, the kept candidates — the next detection builds —, the contacts kept).
template <class Impl>
void rows_changed(Impl& s, std::size_t rows) {
  s.resident_rows = rows;
  s.resident_marked = false;
  s.kept.valid = false;
  s.resident_contacts = {};
  s.resident_on_device.reset();
  s.resident_overwritten = false;
  s.row_list_set.fill(false);
}
}  // namespace

template <class Real>
void Engine<Real>::set_resident(const BodiesView& b) {
  Impl& s = *m_impl;
  const bool shapes = !b.shape.empty();
  check_resident_lengths(b, b.size(), "set_resident");
  for (std::size_t i = 1; i < b.id.size(); ++i)
    if (!(b.id[i] > b.id[i - 1]))
      throw InputError("set_resident: ids are not strictly ascending at row " + std::to_string(i));
  s.resident_shapes = shapes;
  rows_changed(s, b.size());
  if (s.resolved == Backend::cuda) {
    detail::resident_upload(*s.cuda, b);
    return;
  }
  s.resident_position.assign(b.position.begin(), b.position.end());
  s.resident_radius.assign(b.radius.begin(), b.radius.end());
  s.resident_report.assign(b.report.begin(), b.report.end());
  s.resident_shape.assign(b.shape.begin(), b.shape.end());
  s.resident_semi_axes.assign(b.semi_axes.begin(), b.semi_axes.end());
  s.resident_orientation.assign(b.orientation.begin(), b.orientation.end());
  s.resident_id.assign(b.id.begin(), b.id.end());
}

namespace {
// `v`'s rows spliced by `plan` with `arrivals` (stride elements a row), through a pooled array.
template <class T>
void splice_host_rows(HostVector<T>& v, const SplicePlan& plan, std::span<const T> arrivals,
                      std::size_t stride, int threads) {
  HostVector<T> into(plan.size * stride);
  splice_rows(plan, v.data(), arrivals.data(), into.data(), stride, threads);
  v.swap(into);
}
}  // namespace

template <class Real>
void Engine<Real>::splice_resident(std::span<const std::size_t> leaving, std::span<const std::size_t> at,
                                   const BodiesView& b) {
  Impl& s = *m_impl;
  const std::size_t m = b.size();
  const bool shapes = !b.shape.empty();
  check_resident_lengths(b, at.size(), "splice_resident");
  if (s.resident_rows == 0) {  // nothing stays: the arrivals are the rows, whatever fields they carry
    plan_splice(0, leaving, at, "splice_resident");
    set_resident(b);
    return;
  }
  const bool ided =
      s.resolved == Backend::cuda ? detail::resident_view(*s.cuda).id != nullptr : !s.resident_id.empty();
  const bool reported = s.resolved == Backend::cuda ? detail::resident_view(*s.cuda).report != nullptr
                                                    : !s.resident_report.empty();
  if (m > 0 && (shapes != s.resident_shapes || b.id.empty() == ided || b.report.empty() == reported))
    throw UsageError("splice_resident: the arrivals' fields (ids, report, shape rows) differ from the rows'");
  const SplicePlan plan = plan_splice(s.resident_rows, leaving, at, "splice_resident");
  rows_changed(s, plan.size);
  if (s.resolved == Backend::cuda) {
    detail::resident_splice(*s.cuda, leaving, at, b);
    return;
  }
  const int threads = s.options.threads > 0 ? s.options.threads : omp_get_max_threads();
  splice_host_rows(s.resident_position, plan, b.position, 1, threads);
  splice_host_rows(s.resident_radius, plan, b.radius, 1, threads);
  if (reported) splice_host_rows(s.resident_report, plan, b.report, 1, threads);
  if (ided) splice_host_rows(s.resident_id, plan, b.id, 1, threads);
  if (s.resident_shapes) {
    splice_host_rows(s.resident_shape, plan, b.shape, 1, threads);
    splice_host_rows(s.resident_semi_axes, plan, b.semi_axes, 1, threads);
    splice_host_rows(s.resident_orientation, plan, b.orientation, 1, threads);
  }
}

template <class Real>
void Engine<Real>::mark_resident() {
  Impl& s = *m_impl;
  s.resident_marked = true;
  if (s.resolved == Backend::cuda) {
    detail::resident_mark(*s.cuda);
    return;
  }
  const std::size_t n = s.resident_rows;
  s.resident_marked_position.resize(n);
  const Vec3<double>* x = s.resident_position.data();
  Vec3<double>* to = s.resident_marked_position.data();
  const int nt = s.options.threads > 0 ? s.options.threads : omp_get_max_threads();
#pragma omp parallel for num_threads(nt) schedule(static) if (n > (std::size_t(1) << 15))
  for (std::size_t k = 0; k < n; ++k) to[k] = x[k];
}

template <class Real>
ResidentExtent Engine<Real>::resident_extent(std::span<const std::int64_t> ids) {
  Impl& s = *m_impl;
  const std::size_t n = s.resident_rows;
  if (!ids.empty() && ids.size() != n)
    throw UsageError("resident_extent: " + std::to_string(ids.size()) + " ids for " + std::to_string(n) +
                     " resident rows");
  ResidentExtent e;
  if (s.resolved == Backend::cuda) {
    e.bounds = detail::resident_extent(*s.cuda, ids, s.resident_marked, e.displacement);
    return e;
  }
  e.bounds =
      compute_bounds(BodiesView{{s.resident_position.data(), n}, {s.resident_radius.data(), n}, ids, {}});
  if (!s.resident_marked) return e;
  // the largest squared distance (exact: the max of values rounded alike on both backends), then its root
  double moved_sq = 0;
  const Vec3<double>* x = s.resident_position.data();
  const Vec3<double>* x0 = s.resident_marked_position.data();
  const int nt = s.options.threads > 0 ? s.options.threads : omp_get_max_threads();
#pragma omp parallel for num_threads(nt) schedule(static) \
    reduction(max                                         \
              : moved_sq) if (n > (std::size_t(1) << 15))
  for (std::size_t k = 0; k < n; ++k) {
    const Vec3<double> d = x[k] - x0[k];
    moved_sq = std::max(moved_sq, d.x * d.x + d.y * d.y + d.z * d.z);
  }
  e.displacement = std::sqrt(moved_sq);
  return e;
}

template <class Real>
void Engine<Real>::set_skin(double skin) {
  if (!(skin >= 0) || !std::isfinite(skin))
    throw UsageError("skin must be a finite length >= 0 (0: no candidates kept across calls)");
  m_impl->options.skin = skin;
  m_impl->options.skin_auto = false;
}

template <class Real>
void Engine<Real>::rebuild_candidates() {
  m_impl->kept.valid = false;
}

template <class Real>
std::size_t Engine<Real>::resident_size() const {
  return m_impl->resident_rows;
}

namespace {
void check_rows(std::size_t first, std::size_t count, std::size_t rows, const char* what) {
  if (first > rows || count > rows - first)
    throw UsageError(std::string(what) + ": rows " + std::to_string(first) + " + " + std::to_string(count) +
                     " are outside the " + std::to_string(rows) + " resident rows");
}
}  // namespace

template <class Real>
void Engine<Real>::read_resident(std::size_t first, std::size_t count, Vec3<double>* position,
                                 double* radius) {
  Impl& s = *m_impl;
  check_rows(first, count, s.resident_rows, "read_resident");
  if (count == 0) return;
  if (s.resolved == Backend::cuda) {
    detail::resident_copy(*s.cuda, first, count, position, radius, false);
    return;
  }
  std::copy_n(s.resident_position.data() + first, count, position);
  std::copy_n(s.resident_radius.data() + first, count, radius);
}

template <class Real>
void Engine<Real>::write_resident(std::size_t first, std::size_t count, const Vec3<double>* position,
                                  const double* radius) {
  Impl& s = *m_impl;
  check_rows(first, count, s.resident_rows, "write_resident");
  if (count == 0) return;
  if (s.resolved == Backend::cuda) {
    detail::resident_copy(*s.cuda, first, count, const_cast<Vec3<double>*>(position),
                          const_cast<double*>(radius), true);
    return;
  }
  std::copy_n(position, count, s.resident_position.data() + first);
  std::copy_n(radius, count, s.resident_radius.data() + first);
}

template <class Real>
void Engine<Real>::read_resident_shapes(std::size_t first, std::size_t count, Vec3<double>* semi_axes,
                                        Quat<double>* orientation) {
  Impl& s = *m_impl;
  check_rows(first, count, s.resident_rows, "read_resident_shapes");
  if (!s.resident_shapes) throw UsageError("read_resident_shapes: the resident bodies have no shape rows");
  if (count == 0) return;
  if (s.resolved == Backend::cuda) {
    detail::resident_shape_copy(*s.cuda, first, count, semi_axes, orientation, false);
    return;
  }
  if (semi_axes) std::copy_n(s.resident_semi_axes.data() + first, count, semi_axes);
  if (orientation) std::copy_n(s.resident_orientation.data() + first, count, orientation);
}

template <class Real>
void Engine<Real>::write_resident_shapes(std::size_t first, std::size_t count, const Vec3<double>* semi_axes,
                                         const Quat<double>* orientation) {
  Impl& s = *m_impl;
  check_rows(first, count, s.resident_rows, "write_resident_shapes");
  if (!s.resident_shapes) throw UsageError("write_resident_shapes: the resident bodies have no shape rows");
  if (count == 0) return;
  if (s.resolved == Backend::cuda) {
    detail::resident_shape_copy(*s.cuda, first, count, const_cast<Vec3<double>*>(semi_axes),
                                const_cast<Quat<double>*>(orientation), true);
    return;
  }
  if (semi_axes) std::copy_n(semi_axes, count, s.resident_semi_axes.data() + first);
  if (orientation) std::copy_n(orientation, count, s.resident_orientation.data() + first);
}

template <class Real>
std::size_t Engine<Real>::detect_resident(std::optional<Frame> frame) {
  Impl& s = *m_impl;
  if (s.resolved == Backend::cuda) {
    const DeviceBodiesView v = detail::resident_view(*s.cuda);
    s.resident_contacts = Contacts<Real>{};
    // the rows come to the caller through resident_contacts() alone: their device order is free
    s.rows_any_order = true;
    struct AnyOrder {
      bool& flag;
      ~AnyOrder() { flag = false; }
    } any_order{s.rows_any_order};
    const DeviceContactsView<Real> view = detect_device_resident(v, frame);
    s.resident_on_device = view;
    s.resident_overwritten = false;
    return view.count;
  }
  const std::size_t n = s.resident_rows;
  s.resident_contacts = detect_host<Real>(s,
                                          BodiesView{{s.resident_position.data(), n},
                                                     {s.resident_radius.data(), n},
                                                     {},
                                                     {s.resident_report.data(), s.resident_report.size()},
                                                     s.resident_shape,
                                                     s.resident_semi_axes,
                                                     s.resident_orientation},
                                          frame, s.resident_id);
  return s.resident_contacts.size();
}

template <class Real>
const Contacts<Real>& Engine<Real>::resident_contacts() {
  Impl& s = *m_impl;
  if (s.resident_overwritten)
    throw UsageError(
        "resident_contacts: another detection reused the device workspace since detect_resident");
  if (s.resident_on_device) {  // CUDA: downloaded on the first request after the detection
    detail::download_contacts(*s.cuda, *s.resident_on_device, s.resident_contacts);
    s.resident_on_device.reset();
  }
  return s.resident_contacts;
}

template <class Real>
bool Engine<Real>::pin_host(void* p, std::size_t bytes) {
  return m_impl->resolved == Backend::cuda && p && bytes > 0 && detail::pin_host(*m_impl->cuda, p, bytes);
}

template <class Real>
void Engine<Real>::unpin_host(void* p) {
  if (m_impl->resolved == Backend::cuda && p) detail::unpin_host(*m_impl->cuda, p);
}

namespace {
template <class Impl>
int host_threads(const Impl& s) {
  return s.options.threads > 0 ? s.options.threads : omp_get_max_threads();
}
template <class Impl>
detail::RowArrays host_rows(Impl& s) {
  return {s.resident_position.data(), s.resident_radius.data(),
          s.resident_orientation.empty() ? nullptr : s.resident_orientation.data()};
}
// The length of list `list`, set since the rows were set; orientations of listed rows need shape rows.
template <class Impl>
std::size_t listed_rows(const Impl& s, int list, bool orientations, const char* what) {
  if (list < 0 || list >= static_cast<int>(s.row_list_set.size()))
    throw UsageError(std::string(what) + ": no row list " + std::to_string(list));
  if (!s.row_list_set[static_cast<std::size_t>(list)])
    throw UsageError(std::string(what) + ": row list " + std::to_string(list) +
                     " was not set for these rows");
  const std::size_t m = s.row_list_size[static_cast<std::size_t>(list)];
  if (orientations && !s.resident_shapes && m > 0)  // (a rank without rows has none to orient)
    throw UsageError(std::string(what) + ": orientations of rows set without shape rows");
  return m;
}
}  // namespace

template <class Real>
void Engine<Real>::set_row_list(int list, std::span<const std::size_t> rows) {
  Impl& s = *m_impl;
  if (list < 0 || list >= kRowLists) throw UsageError("set_row_list: no row list " + std::to_string(list));
  for (const std::size_t row : rows)
    if (row >= s.resident_rows)
      throw UsageError("set_row_list: row " + std::to_string(row) + " is outside the " +
                       std::to_string(s.resident_rows) + " resident rows");
  const auto l = static_cast<std::size_t>(list);
  if (s.resolved == Backend::cuda)
    detail::rows_set_list(*s.cuda, list, rows);
  else
    s.row_list[l].assign(rows.begin(), rows.end());
  s.row_list_size[l] = rows.size();
  s.row_list_set[l] = true;
}

template <class Real>
std::span<const std::byte> Engine<Real>::gather_rows(int list, bool orientations) {
  Impl& s = *m_impl;
  const std::size_t m = listed_rows(s, list, orientations, "gather_rows");
  if (s.resolved == Backend::cuda) return detail::rows_gather(*s.cuda, list, m, orientations);
  s.row_gathered.resize(m * packed_row_bytes(orientations));
  detail::pack_rows(host_rows(s), s.row_list[static_cast<std::size_t>(list)], orientations,
                    s.row_gathered.data(), host_threads(s));
  return {s.row_gathered.data(), s.row_gathered.size()};
}

template <class Real>
std::span<std::byte> Engine<Real>::scatter_buffer(std::size_t count, bool orientations) {
  Impl& s = *m_impl;
  s.scattered_rows = count;
  s.scattered_orientations = orientations;
  if (s.resolved == Backend::cuda) return detail::rows_scatter_buffer(*s.cuda, count, orientations);
  s.row_scattered.resize(count * packed_row_bytes(orientations));
  return {s.row_scattered.data(), s.row_scattered.size()};
}

template <class Real>
void Engine<Real>::scatter_rows(int list, bool orientations) {
  Impl& s = *m_impl;
  const std::size_t m = listed_rows(s, list, orientations, "scatter_rows");
  if (m > s.scattered_rows || orientations != s.scattered_orientations)
    throw UsageError("scatter_rows: the scatter buffer holds " + std::to_string(s.scattered_rows) +
                     " rows of another layout than the list's " + std::to_string(m));
  if (s.resolved == Backend::cuda) {
    detail::rows_scatter(*s.cuda, list, m, orientations);
    return;
  }
  detail::unpack_rows(s.row_scattered.data(), s.row_list[static_cast<std::size_t>(list)], orientations,
                      host_rows(s), host_threads(s));
}

template <class Real>
void Engine<Real>::copy_rows(Engine& from, int from_list, int to_list, bool orientations) {
  Impl& s = *m_impl;
  Impl& f = *from.m_impl;
  const std::size_t m = listed_rows(s, to_list, orientations, "copy_rows");
  if (listed_rows(f, from_list, orientations, "copy_rows") != m)
    throw UsageError("copy_rows: lists of " +
                     std::to_string(f.row_list_size[static_cast<std::size_t>(from_list)]) + " and " +
                     std::to_string(m) + " rows");
  if (s.resolved != f.resolved) throw UsageError("copy_rows: the engines run on other backends");
  if (s.resolved == Backend::cuda) {
    detail::rows_copy(*s.cuda, *f.cuda, from_list, to_list, m, orientations);
    return;
  }
  detail::copy_rows(host_rows(f), f.row_list[static_cast<std::size_t>(from_list)], host_rows(s),
                    s.row_list[static_cast<std::size_t>(to_list)], orientations, host_threads(s));
}

template <class Real>
std::vector<std::size_t> Engine<Real>::rows_outside(int axis, double lo, double hi) {
  Impl& s = *m_impl;
  if (axis < 0 || axis > 2)
    throw UsageError("rows_outside: axis " + std::to_string(axis) + " is not 0, 1 or 2");
  if (s.resolved == Backend::cuda) return detail::rows_outside(*s.cuda, axis, lo, hi);
  return detail::rows_outside(s.resident_position.data(), s.resident_rows, axis, lo, hi, host_threads(s));
}

template class Engine<float>;
template class Engine<double>;

}  // namespace cg
