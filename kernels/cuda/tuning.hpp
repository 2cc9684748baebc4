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

struct Tuning {
  // CONTACTGRID_CUDA_TYPE_PASSES=1: Le Grand's 8 passes by cell type (opt-in; =0 or unset: the single
  // sort of all entries). About half the device memory a sphere, but slower at every size: 8 compaction
  // fills and 8 sorts cost more than the radix pass they save (BENCHMARKS.md §11).
  bool type_passes = false;
  // CONTACTGRID_DEVICE_MEMORY_LIMIT (bytes) caps the engine's workspace: a smaller GPU, or a GPU
  // shared with a simulation, can be imitated (and the out-of-memory path tested).
  std::optional<std::size_t> memory_limit;
  // CONTACTGRID_CUDA_UPLOAD=registered / pageable: page-lock the host input arrays for the upload
  // always / never (automatic: from 64 MiB an array).
  Forced upload_registered = Forced::automatic;
  // CONTACTGRID_CUDA_RENUMBER=1 / 0: the renumbering of the bodies by z layer on / off (automatic:
  // when the spheres outgrow the L2).
  Forced renumber = Forced::automatic;
  // CONTACTGRID_CUDA_ORDER=counting / radix: group the pairs by a with a counting sort / a radix sort
  // (automatic: counting while its counters fit in half the L2).
  Forced counting_order = Forced::automatic;
  // CONTACTGRID_CUDA_DOWNLOAD=registered / staged: contacts straight into page-locked result vectors /
  // through the pinned staging buffer (automatic: registered from 64 MiB of contacts).
  Forced download_registered = Forced::automatic;
  // CONTACTGRID_CUDA_CANDIDATES=cells: the pair stage proposes every pair the cell rule assigns and
  // the narrow stage rejects the non-touching ones (count → scan → fill): the same contacts, slower;
  // a test knob for the rejecting path (default: spheres_touch, no compaction). =bounding: scenes with
  // ellipsoids keep every bounding-sphere pair (no centre cut, core/centre_cut.hpp): the same contacts.
  CandidateFilter candidates = CandidateFilter::spheres_touch;
  // CONTACTGRID_CUDA_WARP_SOLVE=K: the whole start set of the hard ellipsoid pairs goes one lane group
  // per pair (its starts on the lanes) while there are at most K pairs per resident group, else one
  // thread per pair (cuda/narrow.cuh); 0: always one thread per pair. The same contacts either way.
  // Default 1: a group that takes pairs one after the other loses to a thread per pair (H100).
  unsigned warp_solve_pairs = 1;
};

// `on` / `off` when the variable equals one of the two spellings, else automatic.
inline Forced forced(const char* variable, std::string_view on, std::string_view off) {
  const char* v = std::getenv(variable);
  if (!v) return Forced::automatic;
  if (std::string_view(v) == on) return Forced::on;
  if (std::string_view(v) == off) return Forced::off;
  return Forced::automatic;
}

// The answer of a knob: forced, or `automatic_choice`.
inline bool tuned(Forced f, bool automatic_choice) {
  return f == Forced::automatic ? automatic_choice : f == Forced::on;
}

inline Tuning read_tuning() {
  Tuning t;
  const char* passes = std::getenv("CONTACTGRID_CUDA_TYPE_PASSES");
  t.type_passes = passes && passes[0] == '1';
  if (const char* cap = std::getenv("CONTACTGRID_DEVICE_MEMORY_LIMIT"))
    t.memory_limit = std::strtoull(cap, nullptr, 10);
  t.upload_registered = forced("CONTACTGRID_CUDA_UPLOAD", "registered", "pageable");
  // only the first character counts, as before: "1..." on, "0..." off
  const char* renumber = std::getenv("CONTACTGRID_CUDA_RENUMBER");
  if (renumber && (renumber[0] == '0' || renumber[0] == '1'))
    t.renumber = renumber[0] == '1' ? Forced::on : Forced::off;
  t.counting_order = forced("CONTACTGRID_CUDA_ORDER", "counting", "radix");
  t.download_registered = forced("CONTACTGRID_CUDA_DOWNLOAD", "registered", "staged");
  if (const char* w = std::getenv("CONTACTGRID_CUDA_WARP_SOLVE"))
    t.warp_solve_pairs = static_cast<unsigned>(std::strtoul(w, nullptr, 10));
  if (const char* c = std::getenv("CONTACTGRID_CUDA_CANDIDATES")) {
    const std::string_view v = c;
    if (v == "cells") t.candidates = CandidateFilter::cells;
    if (v == "bounding") t.candidates = CandidateFilter::bounding_spheres;
  }
  return t;
}

}  // namespace cg::detail
