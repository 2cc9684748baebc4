#pragma once
// The plan of the resident steps (comm/resident_steps): what each row a rank holds is for in a step,
// and which rank needs which row. Pure host code (no MPI, no CUDA), unit-tested; made from the run's
// own routing rules (routing.hpp), so the steps hold exactly the ghosts a run from scratch would:
//   to_owner        a row is owned by this rank iff it is the owner of the row's centre coordinate;
//   to_ghost_ranks  an owned row goes, as a ghost, to every other rank within the ghost width.
//
// A rank detects with two engines. Engine A holds its owned rows (interior and boundary) and reports
// all their pairs. Engine B holds the boundary rows and the ghosts, merged in ascending id, and reports
// a pair when the first of it (by id) is owned and not both are boundary rows (A found those):
// report mask kReportedBit | kPairedBit on the boundary rows, 0 on the ghosts. An interior row is
// farther than the ghost width from every other slab, so it touches no ghost: A + B find every contact
// of the rank exactly once, and the owner of the smaller id reports a pair that crosses a cut, as in
// the run (routing.hpp: make_halo_plan's invariant).
//
// With a ghost width per body (GhostRule, the run's per-body halo) the same holds by the anchor rule
// (bodies.hpp): B's mask carries kWideBit on the wide rows, a pair of a wide and a narrow body is
// reported by the narrow one's owner, which holds the wide one (a wide body reaches every slab within
// its radius + r_max); an owned row that a wide ghost may touch is a boundary row too
// (add_wide_partners), as its own width covers narrow partners only.
//
//        rank 0                 rank 1                  rank 2
//   ... interior ... [boundary | ghosts of 1]  [ghosts of 0 | boundary ... interior ... boundary] ...
//                            cut 1 ± width
//
// Rows are held in ascending id (the engine's order: contacts come out sorted by (id_a, id_b), the bits
// of a run from scratch), so engine B's rows interleave boundary rows and ghosts: BoundaryRows says
// where each lands.
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "routing.hpp"
#include "slab_decomposition.hpp"

namespace cg {

// What a held row is for in a step.
enum class RowRole : std::uint8_t {
  interior,  // owned; no other rank's slab within the ghost width: engine A only
  boundary,  // owned; a ghost of at least one other rank (or a wide ghost's partner: add_wide_partners):
             // engine A, engine B, and the halo
  ghost,     // owned by another rank (its owner sends it each step): engine B only
};
const char* to_string(RowRole role);

// The roles of a rank's held rows and its halo.
struct StepPlan {
  std::vector<RowRole> role;          // per held row
  std::size_t owned = 0;              // held rows that are owned (interior or boundary)
  std::vector<std::size_t> boundary;  // held rows that are boundary rows, ascending
  ExportPlan halo;                    // held rows to each other rank (to_ghost_ranks of the owned rows)
  std::size_t count(RowRole r) const;
};

// The plan of rank `self` for its held rows, `coordinate[i]` being row i's centre coordinate along the
// slab axis (finite) and `width` the ghost width (finite, >= 0; InputError otherwise). One parallel
// pass classifies the rows and lists the boundary rows (per chunk of rows, in order), then count →
// scan → fill (route) over the boundary rows alone makes the halo; the result does not depend on the
// threads.
StepPlan make_step_plan(const SlabDecomposition& slabs, int self, std::span<const double> coordinate,
                        double width, int threads = 1);

// The same with a ghost width per row, rule.width(radius[i]) (GhostRule: the run's per-body halo;
// the rule's margin holds the steps' skin): a wide body goes to every slab it reaches, a narrow one
// only as far as narrow partners need it, and engine B reports a pair by its anchor (bodies.hpp: the
// narrow body of a wide and a narrow one), so the wide rows carry kWideBit in B's mask.
StepPlan make_step_plan(const SlabDecomposition& slabs, int self, std::span<const double> coordinate,
                        std::span<const double> radius, const GhostRule& rule, int threads = 1);

// The same plan from the rows that may not be interior, without a pass over the others (the step
// loop lists them where the rows are: Engine::rows_outside of interior_band). `candidates` (ascending,
// each < n) must hold every row that the rule makes a ghost or a boundary row, and may hold interior
// rows; `coordinate[k]` and `radius[k]` are candidate k's. The result is make_step_plan's (by `rule`)
// over all n rows, bit for bit: the other rows are interior. `previous` (a layout's former plan)
// lends its storage.
StepPlan make_step_plan_of(const SlabDecomposition& slabs, int self, std::size_t n,
                           std::span<const std::size_t> candidates, std::span<const double> coordinate,
                           std::span<const double> radius, const GhostRule& rule, int threads = 1,
                           StepPlan previous = {});

// The open interval of centre coordinates whose rows are interior under any ghost width up to
// `max_width` (rank `self`'s slab less max_width at each side, less a margin far above the rounding
// of for_each_ghost_rank's x ± w); the rows outside it are make_step_plan_of's candidates. With
// max_width 0: the rows outside it include every row that `self` does not own.
struct Band {
  double lo, hi;
};
Band interior_band(const SlabDecomposition& slabs, int self, double max_width);

// After the layout's exchange, with a per-body rule: an interior row's own width reaches narrow
// partners only, yet a wide ghost may touch it, and it anchors that pair. Every interior row whose
// centre lies within its radius + a wide ghost's radius + rule.margin of that ghost's centre (along
// the slab axis) becomes a boundary row, so that engine B pairs it with the wide ghosts; it is sent
// nowhere (the halo stays). `wide_coordinate`, `wide_radius`: the wide ghosts' (few: the merged
// intervals they reach, one binary search a row). Returns the rows added.
std::size_t add_wide_partners(StepPlan& plan, std::span<const double> coordinate,
                              std::span<const double> radius, std::span<const double> wide_coordinate,
                              std::span<const double> wide_radius, const GhostRule& rule, int threads = 1);

// Engine B's rows: the boundary rows (ids ascending) and the ghosts (ids grouped by source rank, each
// group ascending, as the halo delivers them) merged in ascending id.
struct BoundaryRows {
  std::vector<std::size_t> of_boundary;  // engine B's row of boundary row k
  std::vector<std::size_t> of_ghost;     // engine B's row of ghost g (in delivery order)
  std::size_t size() const { return of_boundary.size() + of_ghost.size(); }
};

// Throws Error (internal) when an id is held twice or the boundary ids are not ascending. The same
// rows for any number of threads.
BoundaryRows merge_boundary_rows(std::span<const std::int64_t> boundary_ids,
                                 std::span<const std::int64_t> ghost_ids, int threads = 1);

}  // namespace cg
