#pragma once
// The bodies handed to the engine: bounding spheres in host memory (BodiesView) or in CUDA DEVICE
// memory (DeviceBodiesView), and the report mask that decides which rank reports a pair.
// g++-safe public header (part of engine.hpp).
#include <cstddef>
#include <cstdint>
#include <span>

#include "core/vec3.hpp"

namespace cg {

// The bodies handed to the engine: bounding spheres in the world frame (host memory).
// Invariant: ids strictly ascending (so local index order == id order).
// A report mask byte per body (BodiesView::report, DeviceBodiesView::report): a pair (a < b) is
// reported iff report[a] has kReportedBit (the owner of the smaller id reports) and not both
// report[a] and report[b] have kPairedBit (their pairs were found elsewhere: a rank's boundary bodies
// against its ghosts, after its owned bodies were detected alone).
constexpr std::uint8_t kReportedBit = 1, kPairedBit = 2;

struct BodiesView {
  std::span<const Vec3<double>> position;
  std::span<const double> radius;
  std::span<const std::int64_t> id;      // empty: ids are 0 … n-1
  std::span<const std::uint8_t> report;  // empty: all pairs; else see kReportedBit, kPairedBit
  std::size_t size() const { return radius.size(); }
};

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
};

}  // namespace cg
