#pragma once
// The CUDA backend's tuning knobs, read from the environment in one place (read_tuning()). They
// choose among paths that give the same results (measurement and test knobs) or cap the device
// memory the workspace may use. The backend reads them at construction and again at the start of each
// call (CudaBackend::refresh_tuning), so a knob set between two calls on one engine takes effect.
// g++-safe.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <optional>
#include <string_view>

#include "core/narrow.hpp"

namespace cg::detail {

enum class Forced { automatic, off, on };

// How the history stage (cuda/history.cuh) searches the previous step's keys.
enum class HistorySearch { thrust, kernel, near };

// How host arrays cross PCIe (transfer.cuh). streamed: through the engine's ring of pinned slots, the
// host copying one slot while the copy engine moves another; registered: the caller's arrays
// page-locked in place for one copy; single: one copy as it comes (upload: pageable, staged by the
// driver; download: through one whole pinned buffer, then a parallel host copy).
enum class HostTransfer { automatic, streamed, registered, single };

struct Tuning {
  // CONTACTGRID_CUDA_TYPE_PASSES=1: Le Grand's 8 passes by cell type (opt-in; =0 or unset: the single
  // sort of all entries). About half the device memory a sphere, but slower at every size: 8 compaction
  // fills and 8 sorts cost more than the radix pass they save (BENCHMARKS.md §11).
  bool type_passes = false;
  // CONTACTGRID_DEVICE_MEMORY_LIMIT (bytes) caps the engine's workspace: a smaller GPU, or a GPU
  // shared with a simulation, can be imitated (and the out-of-memory path tested).
  std::optional<std::size_t> memory_limit;
  // CONTACTGRID_CUDA_UPLOAD=streamed / registered / pageable: how the host input arrays go up
  // (automatic: streamed from 1 MiB in all, single below).
  HostTransfer upload = HostTransfer::automatic;
  // CONTACTGRID_CUDA_RENUMBER=1 / 0: the renumbering of the bodies by z layer on / off (automatic:
  // when the spheres outgrow the L2).
  Forced renumber = Forced::automatic;
  // CONTACTGRID_CUDA_ORDER=counting / radix: group the pairs by a with a counting sort / a radix sort
  // (automatic: counting while its counters fit in half the L2).
  Forced counting_order = Forced::automatic;
  // CONTACTGRID_CUDA_DOWNLOAD=streamed / registered / staged: how the contact rows come down
  // (automatic: see download_transfer).
  HostTransfer download = HostTransfer::automatic;
  // CONTACTGRID_CUDA_TRANSFER_SLOT=bytes: the size of a slot of the streamed transfers' pinned ring
  // (default 4 MiB; tests use small slots to make a transfer wrap around the ring).
  std::size_t transfer_slot_bytes = std::size_t(4) << 20;
  // CONTACTGRID_CUDA_CANDIDATES=cells: the pair stage proposes every pair the cell rule assigns and
  // the narrow stage rejects the non-touching ones (count → scan → fill): the same contacts, slower;
  // a test knob for the rejecting path (default: spheres_touch, no compaction). =bounding: scenes with
  // ellipsoids keep every bounding-sphere pair (no centre cut, core/centre_cut.hpp): the same contacts.
  CandidateFilter candidates = CandidateFilter::spheres_touch;
  // CONTACTGRID_CUDA_WARP_SOLVE=K: the whole start set of the hard ellipsoid pairs goes one lane group
  // per pair (its starts on the lanes) while there are at most K pairs per resident group, else one
  // thread per pair (cuda/narrow_shapes.cuh); 0: always one thread per pair. The same contacts either way.
  // Default 1: a group that takes pairs one after the other loses to a thread per pair (H100).
  unsigned warp_solve_pairs = 1;
  // CONTACTGRID_CUDA_HISTORY=kernel / thrust: the history stage searches with its own kernel (a
  // binary search per row over all the keys, the fields written in the same kernel) / with Thrust's
  // vectorised lower_bound, then a kernel for the fields; default (near): one kernel whose search
  // starts at the row's own place among the keys (core/history.hpp: lower_bound_key_near). The same
  // fields every way.
  HistorySearch history_search = HistorySearch::near;
  // CONTACTGRID_DEM_SUMS=sort: the granular dynamics' body stage finds each body's rows as B by a
  // radix sort of (B, row) and Thrust's lower_bound of every body id (cuda/dem_sums.cuh); default:
  // counts, their scan and a segmented sort of each body's rows. The same sums either way.
  bool dem_sums_sort = false;
  // The granular dynamics' contact stage (cuda/dem_forces.cuh): by default it stores every term of
  // every row and the body stage sums each body's rows as A and as B (the faster on the H100:
  // BENCHMARKS.md §24); CONTACTGRID_DEM_TERMS=sums: the contact stage sums each body's rows as A
  // itself. The same sums either way.
  bool dem_terms_rows = true;
  // CONTACTGRID_CUDA_NARROW=two-pass: the rejecting narrow stage of sphere scenes with device output
  // counts, scans and fills (two reads of the candidates and their spheres, cuda/narrow.cuh:
  // narrow_compact); default: one pass, a stable compaction with decoupled look-back whose output
  // writes the rows (narrow_select). The same rows either way.
  bool narrow_two_pass = false;
  // CONTACTGRID_STEP_ORDER=file: the resident steps' kept candidates stay in (a, b) order of the
  // input indices (cuda/skin.cuh); default: in the bodies' cell order with the cell-ordered spheres
  // (cuda/cell_order.cuh), the rows sorted by (a, b) when they come down. The same rows either way.
  bool step_order_file = false;
  // CONTACTGRID_STEP_BUILD=copy: a cell-order build's pair stage writes its candidates as input
  // indices where the entries left room (else a second walk fills them in), and the kept list maps
  // them to cell order through the inverse permutation; default: the walk writes the cell-order
  // indices straight into the kept list, sized by the previous build's count (cuda/pairs.cuh). The
  // same rows either way.
  bool step_build_copy = false;
  // CONTACTGRID_STEP_REBUILD=fill: a cell-order build whose walk finds more candidates than the kept
  // list's room writes them by the scan → fill walk (input indices) and maps them to cell order
  // through the inverse permutation, and its room comes from the last kept list alone; default: the
  // same walk again into room of the counted size (cell-order indices in place, no fill walk, no
  // mapping), and the first build's room from the last call's pair count (cuda/pairs.cuh). The same
  // rows either way.
  bool step_rebuild_fill = false;
  // CONTACTGRID_STEP_BUILD_WINDOW=32: the cell-order build's walk tests the 31 entries after each in
  // shared memory, as every other call's (the rest of a longer cell from memory, at the count and again
  // at the write); default 64: 63, found ones kept in a 64-bit set (cuda/pairs.cuh). The same rows
  // either way; CONTACTGRID_STEP_REBUILD=fill implies 32.
  int step_build_window = 64;
  // CONTACTGRID_STEP_NARROW=select: the cell-order narrow stage is CUB's stable select, whose output
  // iterator writes the rows (reading each accepted candidate and its spheres again); default: one
  // kernel that keeps what it read and writes each block's rows at a cursor (cuda/cell_order.cuh:
  // cell_narrow_kernel; the rows' device order is free there). The same rows either way.
  bool step_narrow_select = false;
  // CONTACTGRID_STEP_PACK=separate: a call whose kept list is in cell order checks the motion
  // (motion_kernel), then a reuse packs by a gather through the permutation (pack_cell_kernel);
  // default: one pass in input order does both, each sphere written at its cell place
  // (cuda/cell_order.cuh: motion_pack_cell_kernel). The same spheres and decisions either way.
  bool step_pack_separate = false;
  // CONTACTGRID_STEP_NARROW_ITEMS=2: cell_narrow_kernel tests 2 candidates a thread (fewer registers,
  // more warps an SM) instead of 4 (more loads in flight a warp). The same rows either way.
  int step_narrow_items = 4;
  // CONTACTGRID_DEM_SEGMENTS=cub: the granular dynamics' body index orders each body's rows as B by
  // CUB's segmented sort (which reads its partition back to the host every call); default: one
  // thread per body sorts its own few rows (core/dem_step.hpp: sort_rows), no host synchronisation.
  // The same order either way.
  bool dem_segments_cub = false;
  // CONTACTGRID_DEM_STORE=all: the granular dynamics' contact stage stores every term of every row
  // in double every step; default: only what a later stage reads (cuda/dem_forces.cuh): no torques
  // where the law has no rolling resistance (the body stage takes each from the row's point and
  // force: core/dem_step.hpp, torques_from_points), the normal in the detection's precision, the
  // energy only on a run's last step. The same bits either way.
  bool dem_store_all = false;
  // CONTACTGRID_DEM_BLOCKS=1|2|3: the blocks of 256 threads an SM must hold at once in the granular
  // dynamics' contact and body kernels (__launch_bounds__: their registers capped at 65536 / (256 N),
  // the rest spilled; cuda/dem_forces.cuh). 1: uncapped (about 150 registers a thread: one block an
  // SM). The same bits every way.
  int dem_min_blocks = 2;
  // CONTACTGRID_CUDA_TRACE=1: each detection prints one line on stderr, the host's clock at each
  // stage's queueing beside the stages' event times (StageEvents::trace). A measurement knob.
  bool trace = false;
};

// `on` / `off` when the variable equals one of the two spellings, else automatic.
inline Forced forced(const char* variable, std::string_view on, std::string_view off) {
  const char* v = std::getenv(variable);
  if (!v) return Forced::automatic;
  if (std::string_view(v) == on) return Forced::on;
  if (std::string_view(v) == off) return Forced::off;
  return Forced::automatic;
}

// A transfer knob: the spelling of each choice, else automatic.
inline HostTransfer host_transfer(const char* variable, std::string_view registered,
                                  std::string_view single) {
  const char* v = std::getenv(variable);
  if (!v) return HostTransfer::automatic;
  const std::string_view s(v);
  if (s == "streamed") return HostTransfer::streamed;
  if (s == registered) return HostTransfer::registered;
  if (s == single) return HostTransfer::single;
  return HostTransfer::automatic;
}

// The upload a knob asks for, or the automatic one for `bytes`: streamed from 1 MiB, single below.
inline HostTransfer upload_transfer(const Tuning& t, std::size_t bytes) {
  if (t.upload != HostTransfer::automatic) return t.upload;
  return bytes >= (std::size_t(1) << 20) ? HostTransfer::streamed : HostTransfer::single;
}

// The download a knob asks for, or the automatic one. single (one whole pinned staging buffer of the
// engine, then all host threads copy into the result vectors) where the engine's staging buffer
// already holds the rows or the engine has downloaded before: on a warm engine it beats the streamed
// and registered downloads at every size (BENCHMARKS.md §15). An engine's first download that would
// have to pin its staging buffer does not: pinning hundreds of MB for one call costs more than the copy
// it speeds up (BENCHMARKS.md §20) — the CLI's detect and Python's detect() make one download per
// engine. From 64 MiB it page-locks the result vectors in place after their parallel first touch
// (registered), below that it streams through the process-wide ring (BENCHMARKS.md §21).
inline HostTransfer download_transfer(const Tuning& t, std::size_t staging_bytes, std::size_t bytes,
                                      bool first_download) {
  if (t.download != HostTransfer::automatic) return t.download;
  if (!first_download || bytes <= staging_bytes) return HostTransfer::single;
  return bytes >= (std::size_t(64) << 20) ? HostTransfer::registered : HostTransfer::streamed;
}

// The answer of a knob: forced, or `automatic_choice`.
inline bool tuned(Forced f, bool automatic_choice) {
  return f == Forced::automatic ? automatic_choice : f == Forced::on;
}

inline Tuning read_tuning() {
  Tuning t;
  if (const char* tr = std::getenv("CONTACTGRID_CUDA_TRACE")) t.trace = tr[0] == '1';
  const char* passes = std::getenv("CONTACTGRID_CUDA_TYPE_PASSES");
  t.type_passes = passes && passes[0] == '1';
  if (const char* cap = std::getenv("CONTACTGRID_DEVICE_MEMORY_LIMIT"))
    t.memory_limit = std::strtoull(cap, nullptr, 10);
  t.upload = host_transfer("CONTACTGRID_CUDA_UPLOAD", "registered", "pageable");
  // only the first character counts, as before: "1..." on, "0..." off
  const char* renumber = std::getenv("CONTACTGRID_CUDA_RENUMBER");
  if (renumber && (renumber[0] == '0' || renumber[0] == '1'))
    t.renumber = renumber[0] == '1' ? Forced::on : Forced::off;
  t.counting_order = forced("CONTACTGRID_CUDA_ORDER", "counting", "radix");
  t.download = host_transfer("CONTACTGRID_CUDA_DOWNLOAD", "registered", "staged");
  if (const char* slot = std::getenv("CONTACTGRID_CUDA_TRANSFER_SLOT")) {
    const std::size_t bytes = std::strtoull(slot, nullptr, 10);
    if (bytes >= 4096) t.transfer_slot_bytes = bytes;
  }
  if (const char* w = std::getenv("CONTACTGRID_CUDA_WARP_SOLVE"))
    t.warp_solve_pairs = static_cast<unsigned>(std::strtoul(w, nullptr, 10));
  if (const char* h = std::getenv("CONTACTGRID_CUDA_HISTORY"))
    t.history_search = std::string_view(h) == "kernel"   ? HistorySearch::kernel
                       : std::string_view(h) == "thrust" ? HistorySearch::thrust
                                                         : HistorySearch::near;
  if (const char* d = std::getenv("CONTACTGRID_DEM_SUMS")) t.dem_sums_sort = std::string_view(d) == "sort";
  if (const char* d = std::getenv("CONTACTGRID_DEM_TERMS")) t.dem_terms_rows = std::string_view(d) != "sums";
  if (const char* n = std::getenv("CONTACTGRID_CUDA_NARROW"))
    t.narrow_two_pass = std::string_view(n) == "two-pass";
  if (const char* c = std::getenv("CONTACTGRID_CUDA_CANDIDATES")) {
    const std::string_view v = c;
    if (v == "cells") t.candidates = CandidateFilter::cells;
    if (v == "bounding") t.candidates = CandidateFilter::bounding_spheres;
  }
  if (const char* o = std::getenv("CONTACTGRID_STEP_ORDER"))
    t.step_order_file = std::string_view(o) == "file";
  if (const char* b = std::getenv("CONTACTGRID_STEP_BUILD"))
    t.step_build_copy = std::string_view(b) == "copy";
  if (const char* b = std::getenv("CONTACTGRID_STEP_REBUILD"))
    t.step_rebuild_fill = std::string_view(b) == "fill";
  if (const char* w = std::getenv("CONTACTGRID_STEP_BUILD_WINDOW"))
    t.step_build_window = std::string_view(w) == "32" ? 32 : 64;
  if (const char* m = std::getenv("CONTACTGRID_STEP_NARROW"))
    t.step_narrow_select = std::string_view(m) == "select";
  if (const char* p = std::getenv("CONTACTGRID_STEP_PACK"))
    t.step_pack_separate = std::string_view(p) == "separate";
  if (const char* m = std::getenv("CONTACTGRID_STEP_NARROW_ITEMS"))
    t.step_narrow_items = std::string_view(m) == "2" ? 2 : 4;
  if (const char* d = std::getenv("CONTACTGRID_DEM_SEGMENTS"))
    t.dem_segments_cub = std::string_view(d) == "cub";
  if (const char* d = std::getenv("CONTACTGRID_DEM_STORE")) t.dem_store_all = std::string_view(d) == "all";
  if (const char* d = std::getenv("CONTACTGRID_DEM_BLOCKS")) {
    const long v = std::strtol(d, nullptr, 10);
    if (v >= 1 && v <= 3) t.dem_min_blocks = int(v);
  }
  return t;
}

// The CUDA host-array path (Engine::detect on host arrays), by CONTACTGRID_CUDA_HOST_PATH:
// - device (default): the world doubles go up first, through the pinned ring, and the device takes
//   their bounds (the host reads each input byte once: its own bounds pass cost as much as the
//   upload, BENCHMARKS.md §35); an engine's later downloads, and a first one of 64 MiB or more, go
//   straight into the result vectors' pool blocks, page-locked once (cuda/transfer.cuh:
//   direct_download). Calls with a skin, the contact history or bounds the caller gives keep the
//   host's bounds (kernels/engine.cpp: bodies_go_up_first).
// - packed: the host's bounds, then fp32 sphere calls upload the 16-byte packed spheres, and the rows
//   come down straight into the pool blocks (rows fp32 cannot resolve upload the doubles again).
// - old: the host's bounds, the doubles up by Tuning::upload, the rows down by Tuning::download.
// The same bytes every way; the benchmark's host path table takes each.
enum class HostPath { device, packed, old };
inline HostPath host_path() {
  const char* v = std::getenv("CONTACTGRID_CUDA_HOST_PATH");
  if (v && std::string_view(v) == "packed") return HostPath::packed;
  if (v && std::string_view(v) == "old") return HostPath::old;
  return HostPath::device;
}

}  // namespace cg::detail
