// pieces.cpp: one rank's detection in ranges of bodies that fit a memory limit (see pieces.hpp).
#include "pieces.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <future>
#include <limits>
#include <thread>
#include <vector>

#include "contact_merge.hpp"
#include "host_vector.hpp"

namespace cg {

namespace {

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
void detect_in_pieces(Engine<Real>& engine, const BodiesView& bodies, const Frame& frame,
                      const PieceOptions& o, const std::function<void(Contacts<Real>&&)>& sink,
                      PieceReport* report) {
  PieceReport local;
  PieceReport& rep = report ? *report : local;
  rep = {};
  if (o.memory_limit == 0) {
    rep.pieces = rep.attempts = 1;
    if (o.before_piece) o.before_piece(0);
    Contacts<Real> c = engine.detect(bodies, frame);
    rep.stats = engine.stats();
    rep.times = engine.times();
    sink(std::move(c));
    return;
  }
  if (engine.options().history)
    throw UsageError("a detection in pieces (a memory limit) does not keep contact history");
  const bool full = engine.options().fields == Fields::full;
  const int threads = engine.options().threads > 0 ? engine.options().threads
                                                   : std::max(1, int(std::thread::hardware_concurrency()));
  const std::size_t n = bodies.size();
  const std::uint64_t fixed = piece_bytes<Real>(0, full, n), per_row = piece_bytes<Real>(1, full, 0);
  if (fixed >= o.memory_limit)
    throw ResourceError(
        fmt::format("the {} bodies alone ({}) do not fit in the memory limit of {}; raise --memory-limit", n,
                    bytes_text(fixed), bytes_text(o.memory_limit)));
  // The rows a piece may hold (the model: rows and all bodies within the limit), and the rows planned
  // (80 % of those), lowered after a piece that ran out of memory.
  const std::uint64_t allowed = (o.memory_limit - fixed) / per_row;
  std::uint64_t planned = std::max<std::uint64_t>(1, allowed / 5 * 4);

  // The report bytes the engine sees: the caller's inside the piece's range, without kReportedBit
  // outside it (set and cleared range by range).
  HostVector<std::uint8_t> mask(n);
  bool wide = false;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(|| : wide)
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint8_t given = bodies.report.empty() ? kReportedBit : bodies.report[i];
    mask[i] = static_cast<std::uint8_t>(given & ~kReportedBit);
    wide = wide || (given & kWideBit) != 0;
  }
  auto set_range = [&](std::size_t first, std::size_t last, bool on) {
#pragma omp parallel for num_threads(threads) schedule(static)
    for (std::size_t i = first; i < last; ++i) {
      const std::uint8_t given = bodies.report.empty() ? kReportedBit : bodies.report[i];
      mask[i] = on ? given : static_cast<std::uint8_t>(given & ~kReportedBit);
    }
  };
  BodiesView view = bodies;
  view.report = mask;

  // The blocks go to the sink on a second thread, one at a time: host memory holds the block being
  // handed on and the piece being detected. Unordered pieces (wide bodies) are kept and merged.
  std::future<void> handing;
  std::vector<Contacts<Real>> runs;
  auto hand_on = [&](Contacts<Real>&& c) {
    if (handing.valid()) handing.get();
    if (wide) {
      runs.push_back(std::move(c));
      return;
    }
    handing = std::async(std::launch::async, [&sink, c = std::move(c)]() mutable { sink(std::move(c)); });
  };

  std::uint64_t total = 0;
  double density = 0;         // the most contacts per body of a kept piece so far
  std::uint64_t largest = 0;  // the most rows of a kept piece so far
  std::size_t first = 0;
  try {
    while (first < n) {
      // The piece's bodies: an eighth of the scene first, then as many as the densest piece so far
      // says fit the planned rows.
      std::size_t count = density > 0 ? std::size_t(double(planned) / density) : (n + 7) / 8;
      count = std::clamp<std::size_t>(count, 1, n - first);
      bool halved = false;
      for (;;) {
        if (o.before_piece) o.before_piece(rep.attempts);
        ++rep.attempts;
        set_range(first, first + count, true);
        Contacts<Real> c;
        bool fits = true;
        try {
          c = engine.detect(view, frame);
          fits = c.size() <= allowed;
        } catch (const ResourceError&) {
          // The workspace keeps what the failed stages grew (counted against the limit): a new engine
          // of the same options goes on from nothing.
          engine = Engine<Real>(engine.options());
          fits = false;
        }
        set_range(first, first + count, false);
        if (fits) {
          density = std::max(density, double(c.size()) / double(count));
          // After a piece that did not fit, no later one is planned larger than the half that did.
          if (halved) planned = std::min<std::uint64_t>(planned, std::max<std::size_t>(c.size(), 1));
          // CUDA: the workspace this piece held (the largest so far) against its rows gives the bytes a
          // row takes on the device beyond the model's bodies (an overestimate: the workspace's share
          // that grows with the bodies counts as rows): later pieces are planned at 80 % of that.
          const std::uint64_t held = engine.stats().peak_device_bytes;
          if (held > fixed && c.size() >= largest && c.size() > 0) {
            largest = c.size();
            const double device_row = double(held - fixed) / double(c.size());
            planned = std::min<std::uint64_t>(
                planned,
                std::max<std::uint64_t>(1, std::uint64_t(0.8 * double(o.memory_limit - fixed) / device_row)));
          }
          total += c.size();
          add_stats(rep.stats, engine.stats(), rep.pieces == 0);
          add_times(rep.times, engine.times());
          ++rep.pieces;
          first += count;
          hand_on(std::move(c));
          break;
        }
        if (count == 1) {
          throw ResourceError(fmt::format(
              "the contacts of body {} do not fit in the memory limit of {} beside the {} bodies; raise "
              "--memory-limit",
              bodies.id.empty() ? std::int64_t(first) : bodies.id[first], bytes_text(o.memory_limit), n));
        }
        count /= 2;
        halved = true;
      }
    }
    if (handing.valid()) handing.get();
  } catch (...) {
    if (handing.valid()) handing.wait();  // the block being handed on returns first
    throw;
  }
  rep.stats.bodies = n;
  if (wide) {
    std::vector<ContactRunView<Real>> views;
    for (const Contacts<Real>& run : runs) views.push_back(contact_run_view(run, full));
    Contacts<Real> out;
    out.resize(total, FieldSet(full));
    const std::uint64_t duplicates = merge_contact_runs_into(views, out, full, threads, threads);
    if (duplicates != 0)
      throw Error(
          fmt::format("detect_in_pieces: {} contacts found by two pieces (an internal error)", duplicates));
    runs.clear();
    sink(std::move(out));
  }
  if (o.log)
    o.log(fmt::format("detect: {} contacts in {} pieces under the memory limit of {} ({} detections)", total,
                      rep.pieces, bytes_text(o.memory_limit), rep.attempts));
}

template <class Real>
Contacts<Real> detect_in_pieces(Engine<Real>& engine, const BodiesView& bodies, const Frame& frame,
                                const PieceOptions& o, PieceReport* report) {
  std::vector<Contacts<Real>> runs;
  detect_in_pieces<Real>(
      engine, bodies, frame, o, [&](Contacts<Real>&& c) { runs.push_back(std::move(c)); }, report);
  if (runs.size() == 1) return std::move(runs[0]);
  const bool full = engine.options().fields == Fields::full;
  const int threads = engine.options().threads > 0 ? engine.options().threads
                                                   : std::max(1, int(std::thread::hardware_concurrency()));
  std::vector<ContactRunView<Real>> views;
  std::size_t total = 0;
  for (const Contacts<Real>& run : runs) {
    views.push_back(contact_run_view(run, full));
    total += run.size();
  }
  Contacts<Real> out;
  out.resize(total, FieldSet(full));
  out.full = full;
  merge_contact_runs_into(views, out, full, threads, threads);  // consecutive blocks: a concatenation
  return out;
}

template std::uint64_t piece_bytes<float>(std::uint64_t, bool, std::uint64_t);
template std::uint64_t piece_bytes<double>(std::uint64_t, bool, std::uint64_t);
template Contacts<float> detect_in_pieces(Engine<float>&, const BodiesView&, const Frame&,
                                          const PieceOptions&, PieceReport*);
template Contacts<double> detect_in_pieces(Engine<double>&, const BodiesView&, const Frame&,
                                           const PieceOptions&, PieceReport*);
template void detect_in_pieces(Engine<float>&, const BodiesView&, const Frame&, const PieceOptions&,
                               const std::function<void(Contacts<float>&&)>&, PieceReport*);
template void detect_in_pieces(Engine<double>&, const BodiesView&, const Frame&, const PieceOptions&,
                               const std::function<void(Contacts<double>&&)>&, PieceReport*);

}  // namespace cg
