#pragma once
// The bodies handed to the engine: bounding spheres in host memory (BodiesView) or in CUDA DEVICE
// memory (DeviceBodiesView), and the report mask that decides which rank reports a pair.
// g++-safe public header (part of engine.hpp).
#include <cstddef>
#include <cstdint>
#include <span>

#include "core/quat.hpp"
#include "core/shape.hpp"
#include "core/vec3.hpp"

namespace cg {

// The bodies handed to the engine: bounding spheres in the world frame (host memory).
// Invariant: ids strictly ascending (so local index order == id order).
// A report mask byte per body (BodiesView::report, DeviceBodiesView::report): a pair (a < b) is
// reported iff its anchor's byte has kReportedBit (its owner reports it) and not both report[a] and
// report[b] have kPairedBit (their pairs were found elsewhere: a rank's boundary bodies against its
// ghosts, after its owned bodies were detected alone). The anchor is the smaller id a, unless exactly
// one of the two has kWideBit: then it is the other one, the narrow body (a distributed run sends wide
// bodies, the few large ones, to every slab they reach, and narrow ones only as far as narrow partners
// need them: decomposition/slab_decomposition.hpp, GhostRule). core/broad.hpp: pair_reported.
constexpr std::uint8_t kReportedBit = 1, kPairedBit = 2, kWideBit = 4;

struct BodiesView {
  std::span<const Vec3<double>> position;
  std::span<const double> radius;
  std::span<const std::int64_t> id;      // empty: ids are 0 … n-1
  std::span<const std::uint8_t> report;  // empty: all pairs; else see kReportedBit, kPairedBit
  // Shapes (docs/FORMAT.md §1). Empty `shape`: every body is a sphere of `radius` (the sphere-only fast
  // path). Else one row per body in each of the three (semi_axes and orientation are read for
  // ellipsoids only: a sphere's rows may hold anything) and `radius` is the bounding radius, for an
  // ellipsoid exactly its largest semi-axis. Layout: per-body rows (not an index into ellipsoid
  // arrays): a body's rows move with it (distribute, halo) and the narrow stage reads them by body
  // index with no indirection; a sphere-only scene passes nothing.
  std::span<const Shape> shape = {};
  std::span<const Vec3<double>> semi_axes = {};    // along the body's local x, y, z
  std::span<const Quat<double>> orientation = {};  // unit (w, x, y, z), body → world
  std::size_t size() const { return radius.size(); }
};

// Checks the shape rows of `bodies` (sizes, then per body shape_fault(), core/shape.hpp) and returns
// the number of ellipsoids (0 when `shape` is empty). Throws InputError naming the first bad body by
// id. Run after compute_bounds (which checks centres and radii).
std::size_t validate_shapes(const BodiesView& bodies);

// Bodies already in CUDA DEVICE memory, for simulations that keep their state on the GPU and call
// the engine every step (Engine::detect_device*). Pointers are device pointers on the engine's device
// (EngineOptions::device); the engine only reads them. Body i has id i (local indices).
// Synchronisation: the arrays must be complete when detect_device* is called. Work queued on the
// legacy default stream is ordered before the engine's (blocking) stream; work on a caller's
// non-blocking stream must be synchronised by the caller (cudaStreamSynchronize) first.
struct DeviceBodiesView {
  const double* position = nullptr;      // DEVICE, 3·count doubles: x, y, z of body i at 3i … 3i+2
  const double* radius = nullptr;        // DEVICE, count doubles
  const std::uint8_t* report = nullptr;  // DEVICE, count bytes, or null: all pairs (as BodiesView)
  std::size_t count = 0;
  // Shapes, as BodiesView: null `shape`: all spheres; else semi_axes (3·count doubles) and
  // orientation (4·count doubles, w x y z) of body i at 3i and 4i, read for ellipsoids only.
  const Shape* shape = nullptr;         // DEVICE, count bytes
  const double* semi_axes = nullptr;    // DEVICE
  const double* orientation = nullptr;  // DEVICE
  // Global ids of the bodies (DEVICE, count int64, strictly ascending), or null: body i has id i. Read
  // only as the keys of the contact history (EngineOptions::history); the contacts' ids stay local.
  const std::int64_t* id = nullptr;
};

}  // namespace cg
