#pragma once
// Contacts of any count in bounded memory: one rank's detection in pieces. A piece is a range
// [first, last) of the bodies in id order: every piece hands the engine all bodies with the shared
// frame, and reports only the pairs whose anchor (bodies.hpp: the smaller id a, unless a wide body is
// involved) lies in its range — the broad phase and pair math are those of one detection of all bodies,
// so every contact is found by exactly one piece with the same bytes. With no wide bodies the anchor
// is id_a, so the pieces' sorted rows, in range order, are consecutive blocks of the sorted whole: each
// is handed on as it comes (a sink; the command line appends it to the output file) while the next
// is detected, and nothing is merged. With wide bodies (ghosts of a distributed run) the pieces'
// rows are merged by (id_a, id_b) (contact_merge.hpp) before they are handed on.
//
// How the pieces are sized: a piece's bytes are modelled as its contact rows and all bodies
// (piece_bytes, the same on both backends, so the CPU backend pieces the scenes the CUDA one does);
// each piece takes as many bodies as fit 80 % of the limit at the densest contacts per body seen so far
// (the first piece: an eighth of the bodies). A piece that does not fit — the engine throws
// ResourceError (CUDA: the workspace would pass EngineOptions::device_memory_limit, which the command
// line's --memory-limit sets, or the device's free memory) or its rows take more than the model allows —
// is detected again as its first half, and the pieces after it are no larger than that half. A piece
// of one body that still does not fit, or a limit the bodies alone fill, ends the detection with
// ResourceError (exit code 7) naming the limit. Any other failure of a piece (a device error, the
// sink's) ends it with that error once the piece being handed on has returned.
#include <cstdint>
#include <functional>
#include <string>

#include "engine.hpp"

namespace cg {

struct PieceOptions {
  std::uint64_t memory_limit = 0;               // bytes; 0: one piece, the engine's own detect()
  std::function<void(const std::string&)> log;  // one info line when the scene went in pieces
  // Called before each detection of a piece (0, 1, …), on the calling thread (the run's fault point).
  std::function<void(std::uint64_t piece)> before_piece;
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

// The contacts of `bodies` (ids ascending and report mask as BodiesView: a pair is reported iff its
// anchor is reported; a piece reports the anchors of its range) with the shared `frame`, in pieces that
// fit o.memory_limit, handed to `sink` as consecutive blocks of the sorted rows (their concatenation is
// the one-piece result, row for row). The sink runs on a second host thread while the next piece is
// detected, one call at a time, in order. The engine must not keep contact history
// (EngineOptions::history: UsageError); after a piece that ran out of memory it is replaced by a new
// engine of the same options (its workspace released), so it holds no resident bodies or kept
// candidates afterwards.
template <class Real>
void detect_in_pieces(Engine<Real>& engine, const BodiesView& bodies, const Frame& frame,
                      const PieceOptions& o, const std::function<void(Contacts<Real>&&)>& sink,
                      PieceReport* report = nullptr);

// The same, the blocks gathered into one result.
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
extern template void detect_in_pieces(Engine<float>&, const BodiesView&, const Frame&, const PieceOptions&,
                                      const std::function<void(Contacts<float>&&)>&, PieceReport*);
extern template void detect_in_pieces(Engine<double>&, const BodiesView&, const Frame&, const PieceOptions&,
                                      const std::function<void(Contacts<double>&&)>&, PieceReport*);

}  // namespace cg
