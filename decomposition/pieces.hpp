#pragma once
// Contacts of any count in bounded device memory: one rank's detection in pieces. A piece is a slab of
// space along one axis [lo, hi) — the bodies whose centre lies in it are its owned bodies, and every
// body within the ghost width of it comes along as a ghost — detected by the engine with the shared
// frame, the owner of a pair's anchor reporting it (bodies.hpp), exactly as one rank of an MPI run
// detects its slab (slab_decomposition.hpp). Every contact is found by exactly one piece, with the
// same bytes as a detection of all bodies at once (same frame: same local coordinates, same pair
// math), and the pieces' sorted runs are merged by (id_a, id_b) (contact_merge.hpp): the result is
// the one-piece result, row for row.
//
// How the pieces are chosen: the whole scene is tried first; a piece that does not fit is split into
// slabs of equal owned counts along the axis — two halves, or, where the model below counted the
// bytes the piece needs, as many as those bytes take at 80 % of the limit — and each is tried, depth
// first, in slab order. A piece does not fit when the engine throws ResourceError (CUDA: the workspace
// would pass CONTACTGRID_DEVICE_MEMORY_LIMIT, which the command line's --memory-limit sets, or the
// device's free memory) or when its contact rows and bodies take more than `memory_limit` bytes (the
// model both backends share, so that the CPU backend pieces the same scenes). A piece whose owned
// bodies cannot be split (one body, or all centres equal along the axis) and still does not fit ends
// the detection with ResourceError (exit code 7) naming the limit.
#include <cstdint>
#include <functional>
#include <string>

#include "engine.hpp"

namespace cg {

struct PieceOptions {
  std::uint64_t memory_limit = 0;  // bytes; 0: one piece, the engine's own detect()
  double width = 0;                // ghost width: frame_ghost_width of the scene's bounds and frame
  int axis = 0;                    // slab axis (0 x, 1 y, 2 z)
  std::function<void(const std::string&)> log;  // one info line when the scene went in pieces
};

struct PieceReport {
  std::uint64_t pieces = 0;    // pieces whose contacts were kept
  std::uint64_t attempts = 0;  // detections run (pieces + the ones that did not fit)
  // The engine's statistics of the kept pieces: the last one's, with the counters (entries, pair tests,
  // contacts, candidates, the narrow phase's counts, fp64 rows) summed over the pieces and the largest
  // narrow_max_evaluations; `ellipsoids` counts ghosts once per piece that holds them.
  EngineStats stats;
  StageTimes times;  // the engine's stage times, summed by stage over the kept pieces
};

// The contacts of `bodies` (ids and report mask as BodiesView: a pair is reported iff its anchor is
// reported; a piece reports the anchors it owns) with the shared `frame`, in pieces that fit
// o.memory_limit. The engine must not keep contact history (EngineOptions::history: UsageError); after
// a piece that ran out of memory it is replaced by a new engine of the same options (its workspace
// released), so it holds no resident bodies or kept candidates afterwards.
template <class Real>
Contacts<Real> detect_in_pieces(Engine<Real>& engine, const BodiesView& bodies, const Frame& frame,
                                const PieceOptions& o, PieceReport* report = nullptr);

// Bytes the piece model counts for `rows` contact rows of `fields` in precision Real and `bodies`
// bodies (their positions, radii, ids and report bytes on the device).
template <class Real>
std::uint64_t piece_bytes(std::uint64_t rows, bool full, std::uint64_t bodies);

extern template Contacts<float> detect_in_pieces(Engine<float>&, const BodiesView&, const Frame&,
                                                 const PieceOptions&, PieceReport*);
extern template Contacts<double> detect_in_pieces(Engine<double>&, const BodiesView&, const Frame&,
                                                  const PieceOptions&, PieceReport*);

}  // namespace cg
