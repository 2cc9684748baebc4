// pieces.cpp: one rank's detection in slabs that fit a memory limit (see pieces.hpp).
#include "pieces.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <limits>
#include <thread>
#include <vector>

#include "contact_merge.hpp"
#include "host_vector.hpp"
#include "slab_decomposition.hpp"

namespace cg {

namespace {

// A piece's engine input: owned bodies of [lo, hi) and the ghosts within `width` of it, in input
// order (ascending id), with their ids and report bytes (kReportedBit kept for the owned anchors only).
struct PieceInput {
  HostVector<Vec3<double>> position;
  HostVector<double> radius;
  HostVector<std::int64_t> id;
  HostVector<std::uint8_t> report;
  HostVector<Shape> shape;
  HostVector<Vec3<double>> semi_axes;
  HostVector<Quat<double>> orientation;
  std::vector<double> owned_at;  // the owned bodies' centre coordinates (where a split cuts)

  BodiesView view() const { return BodiesView{position, radius, id, report, shape, semi_axes, orientation}; }
};

// Parallel: each body's role (0 not held, 1 ghost, 2 owned) and the held count per block of rows, a
// scan of the blocks, then each block fills its rows in order.
PieceInput select_piece(const BodiesView& b, int axis, double lo, double hi, double width, int threads) {
  const std::size_t n = b.size(), block = std::size_t(1) << 16, blocks = (n + block - 1) / block;
  std::vector<std::uint8_t> role(n);
  std::vector<std::size_t> held(blocks + 1, 0), owned(blocks + 1, 0);
#pragma omp parallel for num_threads(threads) schedule(static)
  for (std::size_t k = 0; k < blocks; ++k) {
    std::size_t h = 0, o = 0;
    for (std::size_t i = k * block; i < std::min(n, (k + 1) * block); ++i) {
      const double x = component(b.position[i], axis);
      const std::uint8_t r = x < lo - width || x >= hi + width ? 0 : (x >= lo && x < hi ? 2 : 1);
      role[i] = r;
      h += r != 0;
      o += r == 2;
    }
    held[k + 1] = h;
    owned[k + 1] = o;
  }
  for (std::size_t k = 0; k < blocks; ++k) {
    held[k + 1] += held[k];
    owned[k + 1] += owned[k];
  }
  PieceInput p;
  const bool shapes = !b.shape.empty();
  const std::size_t m = held[blocks];
  p.position.resize(m);
  p.radius.resize(m);
  p.id.resize(m);
  p.report.resize(m);
  if (shapes) {
    p.shape.resize(m);
    p.semi_axes.resize(m);
    p.orientation.resize(m);
  }
  p.owned_at.resize(owned[blocks]);
#pragma omp parallel for num_threads(threads) schedule(static)
  for (std::size_t k = 0; k < blocks; ++k) {
    std::size_t w = held[k], o = owned[k];
    for (std::size_t i = k * block; i < std::min(n, (k + 1) * block); ++i) {
      if (role[i] == 0) continue;
      const std::uint8_t given = b.report.empty() ? kReportedBit : b.report[i];
      p.position[w] = b.position[i];
      p.radius[w] = b.radius[i];
      p.id[w] = b.id.empty() ? static_cast<std::int64_t>(i) : b.id[i];
      p.report[w] = role[i] == 2 ? given : static_cast<std::uint8_t>(given & ~kReportedBit);
      if (shapes) {
        p.shape[w] = b.shape[i];
        p.semi_axes[w] = b.semi_axes[i];
        p.orientation[w] = b.orientation[i];
      }
      if (role[i] == 2) p.owned_at[o++] = component(b.position[i], axis);
      ++w;
    }
  }
  return p;
}

// A cut that leaves owned bodies on both sides: the median of their centres, or the next larger centre
// when the median is the smallest. None (NaN) when every centre is the same.
double split_point(std::vector<double>& at) {
  if (at.size() < 2) return std::numeric_limits<double>::quiet_NaN();
  auto mid = at.begin() + static_cast<std::ptrdiff_t>(at.size() / 2);
  std::nth_element(at.begin(), mid, at.end());
  const double m = *mid;
  const double lowest = *std::min_element(at.begin(), at.end());
  if (lowest < m) return m;
  double next = std::numeric_limits<double>::infinity();
  for (double x : at)
    if (x > m) next = std::min(next, x);
  return next == std::numeric_limits<double>::infinity() ? std::numeric_limits<double>::quiet_NaN() : next;
}

// Up to parts - 1 ascending cuts at the quantiles of `at`, each above its smallest value (so that no
// part repeats the whole); empty when none is.
std::vector<double> quantile_cuts(std::vector<double>& at, std::size_t parts) {
  std::vector<double> cuts;
  if (at.size() < 2) return cuts;
  const double lowest = *std::min_element(at.begin(), at.end());
  std::size_t from = 0;
  for (std::size_t j = 1; j < parts; ++j) {
    const std::size_t k = at.size() * j / parts;
    if (k < from) continue;
    std::nth_element(at.begin() + std::ptrdiff_t(from), at.begin() + std::ptrdiff_t(k), at.end());
    from = k;
    const double c = at[k];
    if (c > lowest && (cuts.empty() || c > cuts.back())) cuts.push_back(c);
  }
  return cuts;
}

std::string bytes_text(std::uint64_t b) {
  return b >= (std::uint64_t(1) << 30) ? fmt::format("{:.3g} GiB", double(b) / double(1 << 30))
                                       : fmt::format("{:.3g} MiB", double(b) / double(1 << 20));
}

// `sum` with a piece's statistics `s` (the first piece's: taken as they are).
void add_stats(EngineStats& sum, const EngineStats& s, bool first) {
  if (first) {
    sum = s;
    return;
  }
  const EngineStats before = sum;
  sum = s;
  sum.bodies += before.bodies;
  sum.entries += before.entries;
  sum.pair_tests += before.pair_tests;
  sum.contacts += before.contacts;
  sum.candidates += before.candidates;
  sum.ellipsoids += before.ellipsoids;
  sum.narrow_fallbacks += before.narrow_fallbacks;
  sum.narrow_unconverged += before.narrow_unconverged;
  sum.narrow_unsettled += before.narrow_unsettled;
  sum.narrow_hard += before.narrow_hard;
  sum.narrow_solver_runs += before.narrow_solver_runs;
  sum.narrow_evaluations += before.narrow_evaluations;
  sum.narrow_max_evaluations = std::max(sum.narrow_max_evaluations, before.narrow_max_evaluations);
  sum.fp64_rows += before.fp64_rows;
  sum.narrow_triage_s += before.narrow_triage_s;
  sum.narrow_settle_s += before.narrow_settle_s;
  sum.narrow_hard_s += before.narrow_hard_s;
}

void add_times(StageTimes& sum, const StageTimes& t) {
  for (const StageTime& st : t) {
    auto at = std::find_if(sum.begin(), sum.end(), [&](const StageTime& x) { return x.name == st.name; });
    if (at == sum.end())
      sum.push_back(st);
    else
      at->seconds += st.seconds;
  }
}

}  // namespace

template <class Real>
std::uint64_t piece_bytes(std::uint64_t rows, bool full, std::uint64_t bodies) {
  std::uint64_t row = 0;
  Contacts<Real> probe;
  for_each_contact_field(probe, FieldSet(full), [&](auto, auto& column) { row += sizeof(column[0]); });
  const std::uint64_t body = sizeof(Vec3<double>) + sizeof(double) + sizeof(std::int64_t) + 1;
  return rows * row + bodies * body;
}

template <class Real>
Contacts<Real> detect_in_pieces(Engine<Real>& engine, const BodiesView& bodies, const Frame& frame,
                                const PieceOptions& o, PieceReport* report) {
  PieceReport local;
  PieceReport& rep = report ? *report : local;
  rep = {};
  if (o.memory_limit == 0) {
    rep.pieces = rep.attempts = 1;
    Contacts<Real> c = engine.detect(bodies, frame);
    rep.stats = engine.stats();
    rep.times = engine.times();
    return c;
  }
  if (engine.options().history)
    throw UsageError("a detection in pieces (a memory limit) does not keep contact history");
  const bool full = engine.options().fields == Fields::full;
  const int threads = engine.options().threads > 0 ? engine.options().threads
                                                   : std::max(1, int(std::thread::hardware_concurrency()));
  // One attempt: the contacts, or false when the piece does not fit. `needed`: the bytes the model
  // counted for a piece whose contacts came back too large (0 after a ResourceError: not known).
  std::uint64_t needed = 0;
  auto attempt = [&](const BodiesView& v, Contacts<Real>& out) {
    ++rep.attempts;
    needed = 0;
    try {
      out = engine.detect(v, frame);
    } catch (const ResourceError&) {
      // The workspace keeps what the failed stages grew (sized for this piece, counted against the
      // limit): a new engine of the same options starts the next piece from nothing.
      engine = Engine<Real>(engine.options());
      return false;
    }
    needed = piece_bytes<Real>(out.size(), full, v.size());
    if (needed <= o.memory_limit) return true;
    out = Contacts<Real>{};
    return false;
  };

  Contacts<Real> whole;
  if (attempt(bodies, whole)) {
    rep.pieces = 1;
    rep.stats = engine.stats();
    rep.times = engine.times();
    return whole;
  }
  // The scene in slabs along the axis, each [lo, hi) of centre coordinates.
  struct Range {
    double lo, hi;
  };
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<Range> todo;
  // A piece that does not fit: its parts next, the lowest first (depth first, in slab order). Two
  // halves, or where the model counted the bytes it needs, as many parts of equal owned counts as
  // those bytes take at 80 % of the limit (each part then likely fits at the first try).
  auto split = [&](const Range& r, std::vector<double>& owned_at, std::size_t held) {
    const std::size_t parts =
        needed == 0
            ? 2
            : std::clamp<std::size_t>(std::size_t(double(needed) / (0.8 * double(o.memory_limit))) + 1, 2,
                                      std::max<std::size_t>(owned_at.size(), 2));
    std::vector<double> cuts = quantile_cuts(owned_at, parts);
    if (cuts.empty()) {
      const double cut = split_point(owned_at);
      if (!(cut == cut)) {
        throw ResourceError(fmt::format(
            "the contacts of a piece of {} bodies ({} owned) do not fit in the memory limit of {} and the "
            "piece cannot be split further; raise --memory-limit",
            held, owned_at.size(), bytes_text(o.memory_limit)));
      }
      cuts = {cut};
    }
    double hi = r.hi;
    for (auto c = cuts.rbegin(); c != cuts.rend(); ++c) {
      todo.push_back({*c, hi});
      hi = *c;
    }
    todo.push_back({r.lo, hi});
  };
  {
    std::vector<double> at(bodies.size());
    for (std::size_t i = 0; i < at.size(); ++i) at[i] = component(bodies.position[i], o.axis);
    split({-inf, inf}, at, bodies.size());
  }
  std::vector<Contacts<Real>> runs;
  while (!todo.empty()) {
    const Range r = todo.back();
    todo.pop_back();
    PieceInput p = select_piece(bodies, o.axis, r.lo, r.hi, o.width, threads);
    if (p.owned_at.empty()) continue;  // a piece that owns nothing reports nothing
    Contacts<Real> c;
    if (attempt(p.view(), c)) {
      runs.push_back(std::move(c));
      add_stats(rep.stats, engine.stats(), runs.size() == 1);
      add_times(rep.times, engine.times());
      continue;
    }
    split(r, p.owned_at, p.position.size());
  }
  rep.pieces = runs.size();

  std::vector<ContactRunView<Real>> views;
  std::size_t total = 0;
  for (const Contacts<Real>& run : runs) {
    views.push_back(contact_run_view(run, full));
    total += run.size();
  }
  Contacts<Real> out;
  out.resize(total, FieldSet(full));
  const std::uint64_t duplicates = merge_contact_runs_into(views, out, full, threads, threads);
  if (duplicates != 0)
    throw Error(
        fmt::format("detect_in_pieces: {} contacts found by two pieces (an internal error)", duplicates));
  if (o.log)
    o.log(fmt::format("detect: {} contacts in {} pieces under the memory limit of {} ({} detections)", total,
                      rep.pieces, bytes_text(o.memory_limit), rep.attempts));
  return out;
}

template std::uint64_t piece_bytes<float>(std::uint64_t, bool, std::uint64_t);
template std::uint64_t piece_bytes<double>(std::uint64_t, bool, std::uint64_t);
template Contacts<float> detect_in_pieces(Engine<float>&, const BodiesView&, const Frame&,
                                          const PieceOptions&, PieceReport*);
template Contacts<double> detect_in_pieces(Engine<double>&, const BodiesView&, const Frame&,
                                           const PieceOptions&, PieceReport*);

}  // namespace cg
