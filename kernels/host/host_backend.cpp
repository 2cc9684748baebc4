// The CPU backend: Le Grand's stages on OpenMP threads, over the same core math as the CUDA kernels.
// It is the laptop mode and the oracle for the CUDA backend: every decision (cells, pair rule,
// contact test) and every contact value is computed by the same CG_HD functions in the same order.
//
// Stages (stage.hpp names them for the timing table), one file each in kernels/host/ (stages.hpp):
//   pack      world (double) → local frame Broad spheres; per body: cells, entry count, control byte
//   entries   the cell sort (cell_sort.cpp; the default where the grid has at most about four cells
//             a body and no report mask): the bodies sorted by the super-cell of their lowest cell
//             and their spheres gathered into that order. The entry sort (CONTACTGRID_HOST_ENTRIES=
//             body-order, or the grids it does not take): (cell key, body) entries in body order
//             (scan of entry counts → fill), or, opt-in (=grouped), grouped by the top digit of the
//             key (a counting pass, then each entry to its place)
//   sort      the cell sort: the entries counted and written cell by cell from the bodies' order,
//             with the walk's bodies beside them. The entry sort: stable radix sort of the entries by
//             cell key over plan.key_bits bits (each group by its low bits)
//             (then the pair stage's estimate and its check: pair_estimate.hpp, counted in pairs)
//   pairs     per entry: tests against later entries of its cell (cells of type 0 first: Le Grand's
//             8 passes); candidate pairs (a < b, local indices) collected per chunk of entries,
//             then chunk sizes → scan → fill
//   order     radix sort of the candidates by (a, b)
// The grid's sphere tests without a report mask (every sphere scene on one rank, and the bounding
// spheres of ellipsoid scenes without the centre cut) take the cell list instead (cell_list.cpp,
// cell_walk.cpp): entries = each body's home cell key in a grid of cells a little wider than the widest
// box, sort = those keys and each cell's first place, pairs = each body against its own cell and a half
// stencil of 13 cells, bodies read in cell order; pack then makes no Le Grand cells. The candidates
// are the same (the test decides every pair, and both walks reach every pair the test accepts).
// (BroadPhase::levels: entries, sort and pairs of a grid per level, then the pairs across levels;
// sweep: sort (of the boxes along the axis) and pairs; brute: pairs alone; stages.hpp)
//   narrow    narrow_decide() per candidate, in Narrow (fp64 and mixed: from the world doubles);
//             contact rows in the requested fields, world frame
//             (scenes with ellipsoids: pack also packs the shapes, the pair stage keeps bounding-sphere
//             overlaps, and narrow dispatches on the shape pair: core/shape_narrow.hpp)
// With a skin (EngineOptions::skin, core/skin.hpp): the pair stage tests spheres inflated by
// job.inflation and the ordered list is kept (keep_candidates); a later call first checks the motion
// since (stage skin) and, when the list still covers every contact, runs pack + narrow over it.
#include <omp.h>

#include <cstdlib>
#include <string_view>
#include <type_traits>
#include <utility>

#include "backend.hpp"
#include "host/stages.hpp"
#include "stage.hpp"

namespace cg::detail {
namespace {

// Whether the grid's pair stage takes the cell list (host/cell_list.cpp): the sphere test of (bounding)
// spheres and no report mask, and CONTACTGRID_HOST_PAIRS=cell-list. Opt-in: the same candidates as Le
// Grand's cells, but other entry and pair-test counts than the CUDA backend's (which the stats of both
// backends share), and only a few per cent less CPU time (BENCHMARKS.md §2).
bool cell_list_wanted(CandidateFilter filter, bool no_report) {
  const char* knob = std::getenv("CONTACTGRID_HOST_PAIRS");
  if (knob == nullptr || std::string_view(knob) != "cell-list") return false;
  return no_report &&
         (filter == CandidateFilter::spheres_touch || filter == CandidateFilter::bounding_spheres);
}

// The bodies the narrow stage reads (core/narrow.hpp): fp32 the packed local floats, every mode the
// world doubles of the input; mixed also its broad phase's float spheres and their margin.
template <class Broad, class Narrow>
NarrowBodies<Narrow> narrow_bodies(const BodiesView& bodies, const host::PackedBodies<Broad>& packed,
                                   const Vec3<double>& origin, float broad_margin) {
  NarrowBodies<Narrow> w{nullptr, reinterpret_cast<const double*>(bodies.position.data()),
                         bodies.radius.data(), origin};
  if constexpr (std::is_same_v<Broad, Narrow>) {
    w.spheres = packed.spheres.data();
  } else {  // mixed: its broad phase's floats settle most decisions (touch_fp64)
    w.broad = packed.spheres.data();
    w.broad_margin = broad_margin;
  }
  return w;
}

template <class Broad, class Narrow, class Key>
void run_typed(HostBackend& be, const DetectJob<Broad, Narrow>& job, Contacts<Narrow>& out, StageTimes& times,
               EngineStats& stats) {
  const int nt = be.threads > 0 ? be.threads : omp_get_max_threads();
  HostStageTimer timer(times);
  // Scenes with ellipsoids: candidates are bounding-sphere overlaps (where 4 bodies in 5 are ellipsoids,
  // less the pairs the centre line proves apart: core/centre_cut.hpp; or the looser cell rule), the
  // narrow stage decides per shape pair.
  // Sphere-only scenes: exactly the sphere path; mixed's pair stage takes fp64's decision on its enlarged
  // float spheres (Fp64Touch: the world doubles for the pairs within a few margins of touching), so its
  // candidates are fp64's contacts. A list kept with a skin (inflated spheres): the narrow stage decides.
  const bool shapes = job.ellipsoids > 0;
  const bool skin = job.skin > 0;
  bool reuse = false;
  if (skin && job.check) {  // (a list cut by the centre line: rotations count, core/centre_cut.hpp)
    const Motion m = host::measure_motion(job.bodies, be.kept, nt);
    stats.skin_displacement = m.displacement;
    stats.skin_growth = m.growth;
    if (m.turned) be.kept.turning = true;
    reuse = skin_covers(m, job.skin);
    timer.lap(EngineStage::skin);
  }
  // (after the check: a build of bodies seen turning keeps the bounding spheres, core/skin.hpp)
  const CandidateFilter filter =
      scene_filter(be.candidates, job.ellipsoids, job.bodies.size(), skin, skin_cut_wanted(be.kept.turning));

  host::PackedBodies<Broad> bodies;
  std::vector<PackedShape<Narrow>> packed_shapes;
  // the grid's cells: of the bounding spheres (pack), or in centre-cut scenes without a skin of the
  // shapes' boxes (shape_cells); the other broad phases make their own (levels) or none
  const bool grid = job.broad == BroadPhase::grid;
  const bool cut = filter == CandidateFilter::centre_cut && !reuse;
  const bool box_cells = cut && !skin;
  // fp64 and mixed sphere scenes: the narrow stage reads each contact's second body at random, from
  // pack's world rows (one cache line a body) rather than the input's position and radius arrays
  host::Array<Sphere<double>> world_rows;
  const bool rows_packed = std::is_same_v<Narrow, double> && !shapes;
  // the grid's pair stage of sphere tests without a report mask: the cell list (host/cell_list.cpp),
  // which files each body once and needs none of Le Grand's cells
  const bool list_first = grid && !reuse && cell_list_wanted(filter, job.bodies.report.empty());
  // the cell sort (host/cell_sort.cpp) where it takes the grid: pack then writes each body's block key
  // in place of its cells (a centre cut's cells come from the shapes, the cell list's fallback later)
  const bool by_cells =
      grid && !reuse && host::cell_sort_wanted(job.grid, job.bodies.size(), !job.bodies.report.empty());
  const bool pack_cells = !reuse && !box_cells && grid && !list_first;
  host::pack(job.bodies, job.plan.frame.origin, job.grid, static_cast<Broad>(job.inflation), pack_cells, nt,
             bodies, rows_packed ? &world_rows : nullptr,
             pack_cells && by_cells && host::cell_sort_packs_blocks());
  if (shapes) host::pack_shapes(job.bodies, nt, packed_shapes);
  if (cut) host::cut_shapes(packed_shapes, nt, bodies.cut);
  if (cut && skin) bodies.cut_skin = static_cast<float>(2 * job.inflation);  // (core/centre_cut.hpp)
  if (box_cells && grid) host::shape_cells(job.grid, nt, bodies);
  timer.lap(EngineStage::pack);

  const NarrowBodies<Narrow> world =
      narrow_bodies<Broad, Narrow>(job.bodies, bodies, job.plan.frame.origin, float(job.grid.radius_margin));
  const NarrowBodies<double> world_fp64{nullptr, world.position,    world.radius, world.origin,
                                        nullptr, world.broad_margin};  // mixed's pair test (Fp64Touch)
  host::CandidatePairs built;
  if (!reuse) {
    const NarrowBodies<double>* fp64 = !std::is_same_v<Broad, Narrow> ? &world_fp64 : nullptr;
    built.id_bits = std::max(1, bits_for(bodies.spheres.size()));
    built.filter = filter;
    host::CellList<Broad> cell_list;
    const bool listed = list_first && host::cell_list_keys(bodies, nt, cell_list);
    if (listed) {  // sphere tests, no report mask: the cell list (one entry a body, bodies in cell order)
      stats.entries = cell_list.key.size();
      timer.lap(EngineStage::entries);

      host::sort_cell_list(cell_list, nt);
      timer.lap(EngineStage::sort);

      if (job.pair_limits.wanted()) {
        PairEstimate estimate = host::cell_list_estimate(cell_list, nt);
        estimate.tests_per_second = kHostPairTestsPerSecondPerThread * nt;
        check_pair_estimate(estimate, job.pair_limits);
      }
      stats.pair_tests =
          host::cell_list_candidates(cell_list, bodies, filter, fp64, nt, built, job.pair_limits.on_progress);
      cell_list = {};
      timer.lap(EngineStage::pairs);
    } else if (grid) {
      if (list_first) {  // a body's box spans three cells of the list: Le Grand's cells after all
        cell_list = {};
        host::sphere_cells(job.grid, nt, bodies);
      }
      host::Entries<Key> entries;
      host::EntryBodies<Broad> entry_bodies;  // the cell sort writes them; the entry sort's walk gathers
      if (by_cells) {  // the bodies by super-cell, then the entries by cell from that order
        host::BlockOrder<Broad> order;
        host::block_sort(bodies, job.grid, nt, order);
        timer.lap(EngineStage::entries);

        stats.entries = host::cell_sort(order, job.grid, nt, entries, entry_bodies);
        timer.lap(EngineStage::sort);
      } else {  // the entries in body order, then sorted by key
        stats.entries = host::fill_entries(bodies, job.grid, nt, entries, job.plan.key_bits);
        timer.lap(EngineStage::entries);

        host::sort_entries(entries, job.plan.key_bits, nt);
        timer.lap(EngineStage::sort);
      }

      if (job.pair_limits.wanted()) {
        PairEstimate estimate = host::estimate_pair_tests(entries, job.bodies.size(), nt);
        estimate.tests_per_second = kHostPairTestsPerSecondPerThread * nt;
        check_pair_estimate(estimate, job.pair_limits);
      }
      stats.pair_tests =
          host::find_candidates(entries, bodies, job.bodies.report, job.grid.half_bits, filter, fp64, nt,
                                built, job.pair_limits.on_progress, by_cells ? &entry_bodies : nullptr);
      entries = {};
      entry_bodies = {};
      timer.lap(EngineStage::pairs);
    } else if (job.broad == BroadPhase::levels) {  // a grid per level, then the pairs across levels
      host::Entries<Key> entries;
      host::level_cells(job.levels, nt, bodies);
      stats.entries = host::level_entries(bodies, job.levels, nt, entries);
      timer.lap(EngineStage::entries);

      host::sort_entries(entries, job.plan.key_bits, nt);
      timer.lap(EngineStage::sort);

      if (job.pair_limits.wanted()) {  // the grid's estimate over all cells, and the pairs across levels
        PairEstimate estimate = host::estimate_pair_tests(entries, job.bodies.size(), nt);
        estimate.tests += host::cross_level_estimate(entries, bodies, job.levels, nt);
        estimate.tests_per_second = kHostPairTestsPerSecondPerThread * nt;
        check_pair_estimate(estimate, job.pair_limits);
      }
      stats.pair_tests = host::find_candidates(entries, bodies, job.bodies.report, job.levels.key_shift - 3,
                                               filter, fp64, nt, built);
      stats.pair_tests += host::cross_level_candidates(entries, bodies, job.levels, job.bodies.report, filter,
                                                       fp64, nt, built);
      entries = {};
      timer.lap(EngineStage::pairs);
    } else if (job.broad == BroadPhase::sweep) {
      host::SweepOrder order;
      host::sweep_sort(bodies, job.sweep_axis, nt, order);
      timer.lap(EngineStage::sort);

      if (job.pair_limits.wanted()) {
        PairEstimate estimate = host::sweep_estimate(order, bodies, job.sweep_axis, nt);
        estimate.tests_per_second = kHostPairTestsPerSecondPerThread * nt;
        check_pair_estimate(estimate, job.pair_limits);
      }

      stats.pair_tests =
          host::sweep_candidates(order, bodies, job.sweep_axis, job.bodies.report, filter, fp64, nt, built);
      timer.lap(EngineStage::pairs);
    } else {
      if (job.pair_limits.wanted()) {  // brute force tests every pair
        const std::uint64_t n = job.bodies.size();
        PairEstimate estimate{n * (n - 1) / 2, n, n, n, kHostPairTestsPerSecondPerThread * nt};
        check_pair_estimate(estimate, job.pair_limits);
      }
      stats.pair_tests = host::brute_candidates(bodies, job.bodies.report, filter, fp64, nt, built);
      timer.lap(EngineStage::pairs);
    }

    host::order_candidates(built, nt);
    if (skin) host::keep_candidates(job.bodies, std::move(built), be.kept);
    timer.lap(EngineStage::order);
  }
  if (skin) ++(reuse ? stats.candidate_reuses : stats.candidate_builds);
  const host::CandidatePairs& candidates = skin ? be.kept.pairs : built;  // a build moved its list there
  stats.candidates = candidates.size();

  if (shapes) {
    const ShapeRowsView rows{reinterpret_cast<const double*>(job.bodies.semi_axes.data()),
                             reinterpret_cast<const double*>(job.bodies.orientation.data())};
    host::narrow_shapes(candidates, world, packed_shapes, rows, job.solver, job.fields, nt, out, stats);
  } else {
    host::narrow(candidates, world, job.fields, nt, out, stats, rows_packed ? world_rows.data() : nullptr);
  }
  timer.lap(EngineStage::narrow);
}

}  // namespace

template <class Broad, class Narrow>
void run_stages(HostBackend& backend, const DetectJob<Broad, Narrow>& job, Contacts<Narrow>& out,
                StageTimes& times, EngineStats& stats) {
  if (job.bodies.size() >= (std::size_t(1) << 32))
    throw InputError("more than 2^32 - 1 bodies on one rank; use more MPI ranks");
  if (job.plan.key64)
    run_typed<Broad, Narrow, std::uint64_t>(backend, job, out, times, stats);
  else
    run_typed<Broad, Narrow, std::uint32_t>(backend, job, out, times, stats);
}

template void run_stages(HostBackend&, const DetectJob<float>&, Contacts<float>&, StageTimes&, EngineStats&);
template void run_stages(HostBackend&, const DetectJob<double>&, Contacts<double>&, StageTimes&,
                         EngineStats&);
template void run_stages(HostBackend&, const DetectJob<float, double>&, Contacts<double>&, StageTimes&,
                         EngineStats&);

}  // namespace cg::detail
