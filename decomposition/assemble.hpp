#pragma once
// Assembly of one rank's engine input: its owned bodies and its ghosts in ascending global id, with
// the report mask "owned" (the owner of the smaller id reports a pair). Pure host code, parallel.
#include <cstdint>
#include <span>
#include <vector>

#include "engine.hpp"
#include "routing.hpp"
#include "slab_decomposition.hpp"

namespace cg {

// Per-body shape rows (BodiesView::shape, semi_axes, orientation). Empty: every body is a sphere.
struct ShapeRows {
  HostVector<Shape> shape;
  HostVector<Vec3<double>> semi_axes;
  HostVector<Quat<double>> orientation;
  bool empty() const { return shape.empty(); }
};

// The engine's input in id order: positions, radii, ids, report mask (kReportedBit: owned; kWideBit:
// wide, GhostRule), and the shape
// rows when the scene has ellipsoids (`shapes` empty: all spheres).
// Empty id and report (`implied()`): the rows are bodies 0 … n-1, all owned (the engine's default).
struct EngineInput {
  HostVector<Vec3<double>> position;
  HostVector<double> radius;
  HostVector<std::int64_t> id;
  HostVector<std::uint8_t> report;
  ShapeRows shapes;
  std::uint64_t owned = 0, ghosts = 0;

  bool implied() const { return id.empty(); }
  BodiesView view() const {
    return BodiesView{position, radius, id, report, shapes.shape, shapes.semi_axes, shapes.orientation};
  }
};

// Every-row read: rank `me`'s engine input straight from all N rows (row = id): its owned bodies
// (kReportedBit) and every other body within its ghost width (rule.width of its radius) of the slab,
// ascending id, each with kWideBit when the rule makes it wide — the bodies that redistribution and
// the halo exchange bring, by the same to_owner and to_ghost_ranks rules, without moving any. Parallel count
// → scan → fill. When the rank owns every row (one slab), the rows as read are the input, moved, not copied
// (ids implied; see EngineInput). `shapes`: the rows' shape rows (empty: all spheres), selected with them.
EngineInput select_owned_and_ghosts(HostVector<Vec3<double>>&& position, HostVector<double>&& radius,
                                    const SlabDecomposition& slabs, const GhostRule& rule, int me,
                                    int threads, ShapeRows&& shapes = {});
inline EngineInput select_owned_and_ghosts(HostVector<Vec3<double>>&& position, HostVector<double>&& radius,
                                           const SlabDecomposition& slabs, double width, int me, int threads,
                                           ShapeRows&& shapes = {}) {
  return select_owned_and_ghosts(std::move(position), std::move(radius), slabs, GhostRule::uniform(width), me,
                                 threads, std::move(shapes));
}

// Owned bodies (ascending id: they arrive grouped by source rank, each source sends a subsequence of
// its contiguous row range) and ghosts (grouped by source rank as in `ghost_counts`, each group
// ascending) merged by id straight into the engine's arrays: the ghost groups k-way merged (a few,
// small), then a parallel two-way merge with the owned run. Throws Error if an id is held twice or
// the order is broken (internal errors). `owned_shapes`, `ghost_shapes`: the records' shape rows
// (parallel to `owned` and `ghosts`), or both empty (all spheres). The report mask: kReportedBit on
// the owned, kWideBit on the bodies `rule` makes wide.
EngineInput merge_by_id(std::span<const BodyRecord> owned, std::span<const BodyRecord> ghosts,
                        const std::vector<std::uint64_t>& ghost_counts, int threads,
                        std::span<const ShapeRecord> owned_shapes = {},
                        std::span<const ShapeRecord> ghost_shapes = {},
                        const GhostRule& rule = GhostRule::uniform(0));

}  // namespace cg
