#pragma once
// The order simulate keeps its bodies in (--order): the scene's, or its bodies sorted by the cell of
// their centre (cells of twice the largest bounding radius, x fastest, then y, then z, as a pour's
// lattice is written; spheres before ellipsoids as in the scene, the file's order within a cell).
// The contact and body passes gather each contact's bodies: in cell order a body's partners lie near
// it in memory, so the gathers hit the caches (BENCHMARKS §31: a settled random pack of 2^22
// ellipsoids runs 1.57× faster on the H100 than in the generator's random order). The run is the
// run of the sorted scene: its frames are written back in the scene's order, and a message naming a
// body names it by its id in the scene.
#include <cstdint>
#include <string>
#include <vector>

#include "dem.hpp"

namespace cg {

class BodyOrder {
 public:
  BodyOrder() = default;  // the scene's order
  // The cell order of `bodies` (spheres: the first `spheres` rows).
  static BodyOrder cells(const DemBodies& bodies, std::size_t spheres);

  bool identity() const { return m_scene_of.empty(); }
  // "file", "cells" or "cells-morton": a frame's root attribute body_order (docs/FORMAT.md §6)
  const std::string& name() const { return m_name; }
  // Row k of the run is the scene's row scene_of(k).
  std::int64_t scene_of(std::int64_t k) const {
    return identity() || k < 0 || std::size_t(k) >= m_scene_of.size() ? k : m_scene_of[std::size_t(k)];
  }
  // The bodies in the run's order, and back in the scene's.
  DemBodies to_run(const DemBodies& scene) const;
  DemBodies to_scene(const DemBodies& run) const;
  // `message` with every "body N" naming the scene's row of the run's row N.
  std::string scene_message(const std::string& message) const;

 private:
  std::vector<std::int64_t> m_scene_of;
  std::string m_name = "file";
};

}  // namespace cg
