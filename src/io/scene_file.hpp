#pragma once
// Scene files (docs/FORMAT.md §1): reading (validated, whole or by rows) and writing (whole or streamed).
//
// Reading validates everything it reads and throws InputError with one message naming the file, the
// dataset and the first bad row ("scene.h5: /spheres/radius row 17: radius -1 is not > 0"); a file
// that cannot be opened or is truncated is an InputError naming the file.
// Writing goes to "<path>.tmp.<pid>" and is renamed over <path> only after the file is closed, so an
// output file exists only for a successful run (IoError otherwise, temporary removed).
#include <array>
#include <cstddef>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "engine.hpp"
#include "scene/scene.hpp"

namespace cg {

// Whole scene into memory (double), validated. Rows [first, first+count) of each group can be read
// with read_scene_rows for parallel readers.
Scene read_scene(const std::string& path);

// Counts of bodies in a scene file without reading the data (datasets' types and shapes are checked;
// a file without bodies is an InputError, like read_scene).
struct SceneShape {
  std::size_t spheres = 0, ellipsoids = 0;
};
SceneShape read_scene_shape(const std::string& path);

// Rows [first, first + count) of /spheres (positions, radii) — validated like read_scene, with the
// row numbers of the file in messages. Root attributes are read too.
// Rows count in global body ids (spheres 0 … N-1, then ellipsoids N … N+M-1), so for a file with
// only spheres they are exactly the rows of /spheres; a range crossing N returns the spheres
// [first, N) and the ellipsoids [0, first+count-N) of /ellipsoids. A range past N+M is a UsageError.
Scene read_scene_rows(const std::string& path, std::size_t first, std::size_t count);

// The engine's input rows of a scene (BodiesView), in id order: spheres 0 … N-1, then ellipsoids.
// Without shapes (`shapes` false; only for a scene without ellipsoids) the sphere rows are moved out
// of the scene (no copy) and the shape rows stay empty: the sphere-only path. With shapes, one row
// per body in each: spheres Shape::sphere, semi-axes (r, r, r), identity orientation; ellipsoids
// Shape::ellipsoid, radius = the largest semi-axis (the bounding radius, exactly as shape_fault wants).
struct BodyRows {
  HostVector<Vec3<double>> position;
  HostVector<double> radius;
  HostVector<Shape> shape;  // empty: all spheres
  HostVector<Vec3<double>> semi_axes;
  HostVector<Quat<double>> orientation;
  std::size_t size() const { return radius.size(); }
};
BodyRows body_rows(Scene&& scene, bool shapes);

// Writes float64 datasets ((N,3) / (N)), root attributes radius_low/radius_high when set and every
// entry of scene.attributes (keys "radius_low"/"radius_high" there are ignored: the optionals rule).
// Writing does not validate the values (tests write bad scenes on purpose). A scene without bodies
// is written as an empty /spheres group. IoError on failure, no file left behind.
void write_scene(const std::string& path, const Scene& scene);

// What a scene file holds besides its rows: the body counts (the datasets' final sizes) and the root
// attributes.
struct SceneFileHeader {
  std::size_t spheres = 0, ellipsoids = 0;
  std::optional<double> radius_low, radius_high;
  Attributes attributes;
};

// Streams a scene file of known size in row blocks, in bounded host memory (generate_scene_file,
// 2^28 bodies). Datasets of the final sizes are created by the constructor; every row must be
// written once (blocks in any order); commit() closes the temporary "<path>.tmp.<pid>" and renames
// it over path. Destroyed without commit(), the temporary is removed. Throws IoError.
class SceneFileWriter {
 public:
  SceneFileWriter(const std::string& path, const SceneFileHeader& header);
  ~SceneFileWriter();
  SceneFileWriter(const SceneFileWriter&) = delete;
  SceneFileWriter& operator=(const SceneFileWriter&) = delete;

  void write_spheres(std::size_t first, std::span<const Vec3<double>> position,
                     std::span<const double> radius);
  void write_ellipsoids(std::size_t first, std::span<const Vec3<double>> position,
                        std::span<const Vec3<double>> semi_axes,
                        std::span<const std::array<double, 4>> orientation);
  void commit();

  struct Impl;

 private:
  std::unique_ptr<Impl> m_impl;
};

}  // namespace cg
