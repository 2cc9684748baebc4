// The summary stage of `contactgrid detect` (summary.hpp).
#include "run/summary.hpp"

#include <fmt/format.h>

#include <string>

namespace cg {

namespace {

// The resident steps' lines: what moved and what was checked, the per-step stage times, the candidate
// lists (builds, reuses, the skin) and, with moving bodies on several ranks, the rebuilds.
void print_steps(const StepStats& s, int ranks) {
  std::string checked;
  if (s.drift != 0)
    checked = fmt::format(
        "the bodies drifting {} per step{}, {} contacts on the last step (the output; pair hash "
        "{:016x})",
        s.drift, s.turned ? fmt::format(" and the ellipsoids turning {} rad", s.spin) : "", s.contacts,
        s.hash);
  else if (s.turned)
    checked = fmt::format(
        "the ellipsoids turning {} rad per step, {} contacts on the last step (= the turned bodies detected "
        "from scratch)",
        s.spin, s.contacts);
  else
    checked = fmt::format("{} contacts per step (= the file's)", s.contacts);
  fmt::print(
      "resident steps: {} (bodies kept in each rank's engine), {}, {} ghost rows{} refreshed per step; "
      "setup {:.6f} s; per step, median of the maxima over ranks:\n",
      s.steps, checked, s.halo_rows, s.oriented ? " (with orientations)" : "", s.setup);
  if (s.drift != 0) fmt::print("  {:<16} {:>12.6f}\n", "frame", s.frame);
  if (s.rebuilds > 0 && ranks > 1) {
    fmt::print("  {:<16} {:>12.6f}  (the steps that rebuilt: rebalance and migration)\n", "migrate",
               s.migrate);
    fmt::print(
        "    {:<14} {:>12.6f}  (the steps that waited for the host rows' merge: it runs beside the "
        "layout and the detection)\n",
        "merge wait", s.merge_wait);
  }
  if (s.rebuilds > 0)
    fmt::print("  {:<16} {:>12.6f}  (the steps that rebuilt: check and layout)\n", "rebuild", s.rebuild);
  fmt::print("  {:<16} {:>12.6f}\n", "halo", s.halo);
  if (ranks > 1)  // its parts: the rows gathered and packed, the MPI exchange, the rows into engine B
    fmt::print("    {:<14} {:>12.6f}  ({})\n    {:<14} {:>12.6f}\n    {:<14} {:>12.6f}\n", "halo pack",
               s.halo_pack, s.halo_on_device ? "where the rows are" : "on the host", "halo mpi", s.halo_mpi,
               "halo unpack", s.halo_unpack);
  fmt::print("  {:<16} {:>12.6f}\n", "interior", s.interior);
  for (const StageTime& t : s.stages) fmt::print("    {:<14} {:>12.6f}\n", t.name, t.seconds);
  fmt::print("  {:<16} {:>12.6f}\n  {:<16} {:>12.6f}\n", "boundary", s.boundary, "step", s.step);
  fmt::print(
      "  candidate lists: {} builds, {} reuses, skin {:.6g}{}; mean step {:.6f} s (without the frame {:.6f} "
      "s), detection {:.6f} s building, {:.6f} s reusing\n",
      s.builds, s.reuses, s.skin, s.skin_auto ? " (auto)" : "", s.step_mean, s.detect_mean, s.detect_build,
      s.detect_reuse);
  if (s.builds > 0 && s.reuses > 0) {  // the stages above are a reusing step's: a building step's too
    std::string line;
    for (const StageTime& t : s.build_stages) line += fmt::format(" {} {:.6f}", t.name, t.seconds);
    fmt::print("  a building step's stages (s, median):{}\n", line);
  }
  if (ranks > 1 && s.drift != 0)
    fmt::print(
        "  {} rebuilds, {} bodies migrated, {} slab rebalances; owned bodies per rank at the end {} … {}\n",
        s.rebuilds, s.migrated, s.rebalances, s.owned_min, s.owned_max);
}

}  // namespace

template <class Real>
void print_summary(const RunInfo& info, const RunTimes& times, std::uint64_t contacts,
                   const DistributedResult<Real>& r) {
  fmt::print("contactgrid detect: {} bodies, {} contacts ({:.3f} per body), {} rank(s), backend {}, {}\n",
             info.bodies, contacts, info.bodies ? double(contacts) / double(info.bodies) : 0.0, info.ranks,
             info.backend, info.precision);
  if (!info.precision_choice.empty()) fmt::print("  {}\n", info.precision_choice);
  fmt::print("  cell size {:.6g}", info.cell_size);
  if (r.ranks > 1)
    fmt::print(", read {}, slab axis {}, owned bodies per rank {} … {}, ghosts {}, duplicates removed {}",
               r.read == SceneRead::all_rows ? "all rows per rank" : "own rows", "xyz"[r.axis], r.owned_min,
               r.owned_max, r.ghosts, r.duplicates_removed);
  if (r.memory_limit > 0)
    fmt::print("\n  {} pieces under --memory-limit {:.4g} MiB ({} detections{})", r.pieces,
               double(r.memory_limit) / double(1 << 20), r.piece_detections,
               r.ranks > 1 ? "; the most on a rank" : "");
  if (r.ellipsoids > 0)
    fmt::print("\n  {} ellipsoids, {} narrow fallbacks, {} narrow solves unconverged (summed over ranks)",
               r.ellipsoids, r.stats.narrow_fallbacks, r.stats.narrow_unconverged);
  if (r.stats.narrow_solver_runs > 0)
    fmt::print("\n  ellipsoid solver: {} runs, {:.1f} evaluations of f per run, at most {} in one",
               r.stats.narrow_solver_runs,
               double(r.stats.narrow_evaluations) / double(r.stats.narrow_solver_runs),
               r.stats.narrow_max_evaluations);
  if (r.stats.fp64_rows > 0)
    fmt::print(
        "\n  {} fp32 rows recomputed in fp64 (centres closer than fp32 resolves a normal; summed over "
        "ranks)",
        r.stats.fp64_rows);
  fmt::print("\n  broad phase {}{}, {}-bit cell keys, {} (cell, body) entries, {} pair tests{}\n",
             to_string(r.stats.broad_phase),
             r.stats.broad_phase == BroadPhase::levels ? fmt::format(" ({} levels)", r.stats.levels) : "",
             r.stats.key_bits, r.stats.entries, r.stats.pair_tests,
             r.ranks > 1 ? "; times: maximum over ranks" : "");
  // One rank moves nothing: the stages that send (redistribute, halo, gather or exchange, merge) are
  // left out of its table. Reading every row (--read all), a rank selects its owned bodies and its
  // ghosts in one pass ("select"), and no halo is exchanged.
  const bool all_rows = r.read == SceneRead::all_rows;
  auto shown = [&](RunStage s) {
    if (r.ranks == 1)
      return s != RunStage::redistribute && s != RunStage::halo && s != RunStage::gather &&
             s != RunStage::exchange && s != RunStage::merge;
    return !(all_rows && s == RunStage::halo);
  };
  double total = 0;
  fmt::print("  {:<16} {:>12}\n", "stage", "seconds");
  for (const RunTime& t : times) {
    const bool sub = t.engine_stage >= 0;  // the engine's stages, inside "detect"
    if (!sub) total += t.seconds;
    if (!shown(t.stage)) continue;
    const std::string name = sub ? "  " + engine_stage_names()[static_cast<std::size_t>(t.engine_stage)]
                             : r.ranks > 1 && all_rows && t.stage == RunStage::redistribute
                                 ? std::string("select")
                                 : std::string(stage_name(t.stage));
    fmt::print("  {:<16} {:>12.6f}\n", name, t.seconds);
  }
  fmt::print("  {:<16} {:>12.6f}\n", "total", total);
  if (r.warm_up > 0)  // outside the table, as a new process's context creation is
    fmt::print(
        "  (the device made ready on a thread of its own while the scene was read: {:.3f} s, its context "
        "{:.3f} s, the kernels' loads the rest; then the run waited {:.3f} s for it)\n",
        r.warm_up, r.warm_up_context, r.warm_up_wait);
  if (r.ranks > 1 && all_rows)
    fmt::print(
        "  (select: every rank read every row and kept its owned bodies and its ghosts; no halo exchange)\n");
  if (r.steps.steps > 0) print_steps(r.steps, r.ranks);
}

template void print_summary<float>(const RunInfo&, const RunTimes&, std::uint64_t,
                                   const DistributedResult<float>&);
template void print_summary<double>(const RunInfo&, const RunTimes&, std::uint64_t,
                                    const DistributedResult<double>&);

}  // namespace cg
