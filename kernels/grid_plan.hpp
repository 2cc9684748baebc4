#pragma once
// The grid of one detection: bounds of the bodies, the shared frame (origin, cell edge, and the
// cell-size model that chooses it), and the grid plan (dims, key width). Host code (grid_plan.cpp);
// g++-safe public header (part of engine.hpp).
#include <cstddef>
#include <cstdint>

#include "bodies.hpp"
#include "core/vec3.hpp"
#include "precision.hpp"

namespace cg {

// Axis-aligned bounds of the bounding spheres' boxes, and the largest and smallest radius.
struct Bounds {
  Vec3<double> lo{0, 0, 0}, hi{0, 0, 0};
  double r_max = 0;
  double r_min = 0;  // the smallest bounding radius (--precision auto: accuracy relative to it)
  std::size_t count = 0;
  double r_sum[3] = {0, 0, 0};  // Σ r, Σ r², Σ r³: the radius moments of the cell-size model
  void merge(const Bounds& o);
};

// Validates every body (finite centre, finite radius > 0) and returns the bounds.
// Throws InputError naming the first bad body by id.
Bounds compute_bounds(const BodiesView& bodies);
// Whether ids are strictly ascending: compute_bounds' check of the ids alone, as a parallel pass over
// `threads` OpenMP threads (0: all) that names nothing (compute_bounds names the first that is not).
bool ids_ascending(std::span<const std::int64_t> id, int threads);

// The shared frame of a run: local origin (double) and cell edge. Every rank of an MPI run uses the
// same frame, so every rank computes bit-identical local coordinates and contact data.
struct Frame {
  Vec3<double> origin{0, 0, 0};
  double cell_size = 0;
};

// Smallest valid cell edge for these bounds: 2·r_max plus a margin that covers the rounding of
// c ± r in the local frame, so a body never spans more than two cells per axis (mixed: of the radius
// enlarged by broad_margin()).
double min_cell_size(const Bounds& b, Precision p);

// mixed: what the fp32 broad phase adds to every radius so that its float test keeps every pair that
// touches in exact arithmetic (and every pair fp64 decides is a contact): 4·ε32·(L + 2·r_max), L the
// largest |coordinate| of the bodies relative to `origin` (docs/PRECISION.md derives it).
// 0 for fp32 and fp64.
double broad_margin(const Bounds& b, const Vec3<double>& origin, Precision p);

// fp32 writes world positions as float32: refuses (InputError, exit 3) scenes whose largest world
// coordinate X makes the float32 spacing ulp32(X) larger than a quarter of the largest radius (from
// |X| ≈ 2^21 for r_max = 1: 1e8 is refused, 1e6 is not), naming the offset and the other modes.
void check_fp32_world(const Bounds& b, Precision p);

// How the cell edge is chosen when none is requested (EngineOptions::cell_size = 0).
enum class CellChoice {
  tuned,     // tuned_cell_size(): the edge that minimises the modelled cost of the sort and pair stages
  smallest,  // min_cell_size(): the largest diameter + rounding margin (Le Grand's choice)
};

// The cell edge in [1, 3] × min_cell_size() that minimises a cost model of the stages that depend on
// it, per body: e + kPairWeight · N · e² / cells, where e = E[(1 + 2r/c)³] is the expected number of
// (cell, body) entries per body (exact for uniformly placed centres, from the radius moments),
// N · e² / cells twice the expected pair-walk steps per body (Poisson occupancy of the cells that
// cover the bounds), and kPairWeight the measured cost of a walk step relative to one entry
// (sort + fill). Larger cells mean fewer entries to sort but more pairs to walk: dilute scenes of
// similar radii gain ~2× larger cells, dense or strongly polydisperse ones keep the smallest. Only
// speed depends on the choice: contacts are the same for every valid cell edge.
double tuned_cell_size(const Bounds& b, Precision p);
inline constexpr double kPairWeight =
    0.03;  // fit: H100, 2^24 uniform spheres, fp32, cells 3–6 (BENCHMARKS §3)

// Frame for the bounds; requested_cell_size 0 picks the cell by `choice`. Throws UsageError if the
// requested size is too small, InputError if the grid cannot be encoded (see GridPlan).
Frame make_frame(const Bounds& b, double requested_cell_size, Precision p,
                 CellChoice choice = CellChoice::tuned);

// The grid of one detect() call: cells covering the bodies' bounds in the shared frame.
// Cell keys use 32 bits when the grid has < 2^32 cells, else 64 bits (< 2^63 cells); beyond that,
// or beyond 2^22 cells per axis in fp32 (2^40 in fp64), plan_grid() throws InputError.
struct GridPlan {
  Frame frame;
  std::uint32_t base[3] = {0, 0, 0};  // cell coordinate (even) of the grid's first cell in the frame
  std::uint32_t dims[3] = {1, 1, 1};
  std::uint32_t half[3] = {1, 1, 1};
  int half_bits = 0;
  int key_bits = 3;
  bool key64 = false;
  std::uint64_t cell_count() const { return std::uint64_t(dims[0]) * dims[1] * dims[2]; }
};
GridPlan plan_grid(const Bounds& local, const Frame& frame, Precision p);

}  // namespace cg
