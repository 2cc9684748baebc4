#pragma once
// Bullet 3 as the oracle for sphere and ellipsoid contacts (docs/FORMAT.md §4), behind an interface without
// Bullet types. A sphere is a btSphereShape; an ellipsoid is an EllipsoidShape
// (bullet_ellipsoid_shape.hpp): the exact support R D² Rᵀ u / |D Rᵀ u| with a collision margin of
// kEllipsoidMargin folded into it, so Bullet's margin-inflated shape is the ellipsoid itself.
//
// bullet_oracle.cpp is compiled twice: once against double Bullet (pkg-config bullet-float64, which
// adds -DBT_USE_DOUBLE_PRECISION) into cg_validate, and once against float Bullet (pkg-config bullet)
// into the small executable `contactgrid-bullet-float`. The two Bullet flavours export the same
// symbols, so they can never share one process: the float oracle is always run as a subprocess,
// exchanging data through two temporary binary files (format below).
//
// Invariants of a result:
//   - every contact has id_a < id_b (Bullet's body A is the body added first; bodies are added in
//     id order; a pair Bullet ever reports the other way round is swapped: points swapped, normal
//     negated), one row per pair (the deepest manifold point), rows sorted by (id_a, id_b);
//   - only manifold points with distance <= 0 are reported, and no pair of two partners;
//   - positions, normals and distances are Bullet's own values (btManifoldPoint positionWorldOnA/B,
//     normalWorldOnB, distance1) converted to double and brought back from Bullet's frame (below) to
//     the scene's: positions / scale + origin, distances / scale.
//
// Bullet's frame: Bullet sees every body at (centre − origin) · scale with its lengths (radius,
// semi-axes) · scale. Its own thresholds are absolute lengths (the contact breaking threshold 0.02 by
// which it grows every box and keeps manifold points, the ellipsoid margin kEllipsoidMargin): with
// grains of radius 0.001 a box grown by 0.02 overlaps hundreds of others, and every overlapping pair
// costs Bullet a manifold (~1.5 KB in double). The validation picks the scale as a power of two
// (exact in binary: the frame changes no digit of the scene) that brings the bodies' mean bounding
// radius near 1, the size those thresholds were made for, and the origin at the middle of the bodies
// it hands over (float Bullet is exact only near its origin).
//
// Locating the float executable (bullet_float_executable()):
//   1. $CONTACTGRID_BULLET_FLOAT if set (must name an executable file);
//   2. `contactgrid-bullet-float` next to the running executable (/proc/self/exe), i.e. the install
//      layout (bin/contactgrid, bin/contactgrid-bullet-float);
//   3. the path the build tree gave it (compile definition CG_BULLET_FLOAT_BUILD_PATH), for tests.
//
// Exchange format (native endianness; both processes run on the same host):
//   input : "CGBOIN03", u64 n, u8 warm, f64 origin[3], f64 scale,
//           n × {f64 x, y, z, r, semi_a, semi_b, semi_c, qw, qx, qy, qz}, n × i64 id, n × u8 partner
//           (a sphere has semi-axes 0; an ellipsoid has r = its largest semi-axis)
//   output: "CGBOOUT2", u32 sizeof(btScalar), f64 scratch_s, f64 warm_s (-1: not run), u64 pairs,
//           u64 peak resident bytes of the writer, u64 k,
//           k × {i64 id_a, i64 id_b, f64 pa[3], f64 pb[3], f64 n[3], f64 distance}
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/vec3.hpp"
#include "engine.hpp"

namespace cg {

struct Scene;

// The collision margin of an ellipsoid in Bullet (measured, issue #12: float Bullet with the exact
// support and this margin agrees best with the exact contacts), shrunk per body to half its smallest
// radius of curvature c_min² / a_max so that the margin-free core stays convex.
inline constexpr double kEllipsoidMargin = 0.04;

// Bodies handed to Bullet, in the scene's coordinates. Invariant: ids strictly ascending. `semi_axes`
// and `orientation` are empty (every body a sphere) or one row per body; a row with semi-axes
// (0, 0, 0) is a sphere of `radius`, any other an ellipsoid (radius = its largest semi-axis,
// orientation the unit quaternion (w, x, y, z) of docs/FORMAT.md §1). Bullet sees `(position − origin) ·
// scale` and lengths · scale (Bullet's frame, above); what it returns is brought back in double.
struct OracleBodies {
  std::vector<Vec3<double>> position;
  std::vector<double> radius;
  std::vector<Vec3<double>> semi_axes;
  std::vector<std::array<double, 4>> orientation;
  std::vector<std::int64_t> id;
  Vec3<double> origin{0, 0, 0};
  double scale = 1;                   // a power of two (bullet_scale)
  std::vector<std::uint8_t> partner;  // empty, or per body 1: a partner only, which Bullet pairs with
                                      // the other bodies but never with another partner (its collision
                                      // filter group): the margin of a piece
  std::size_t size() const { return radius.size(); }
  bool is_ellipsoid(std::size_t i) const { return !semi_axes.empty() && semi_axes[i].x > 0; }
};

struct OracleResult {
  Contacts<double> contacts;           // sorted, id_a < id_b, distance <= 0
  int scalar_bytes = 8;                // sizeof(btScalar) of the Bullet that produced them (8 or 4)
  double scratch_seconds = 0;          // world construction + adding bodies + first detection
  double warm_seconds = -1;            // one warm step (move every body slightly, detect again); -1: not run
  std::uint64_t pairs = 0;             // Bullet's overlapping pairs (each holds a manifold): its memory
  std::uint64_t child_peak_bytes = 0;  // float Bullet: the subprocess's peak resident memory; 0 in process
};

// The scale of Bullet's frame for bodies of mean bounding radius `r_mean` (> 0): the power of two
// nearest 1 / r_mean (so the scaled mean radius lies in [0.7, 1.4]).
double bullet_scale(double r_mean);
// bullet_scale of a scene's mean bounding radius (defined in validate.cpp).
double bullet_scale_of(const Scene& scene);

// The bodies `ids` (ascending) of a scene for Bullet (ellipsoids with their semi-axes and
// orientation when the scene has any), in Bullet's frame of `scale` centred on the middle of their
// centres' box; `extent` gets the largest |centre − origin| (scene units). Defined in validate.cpp
// (cg_validate; used by validate and bench).
OracleBodies oracle_bodies(const Scene& scene, const std::vector<std::int64_t>& ids, double scale,
                           double& extent);

// Runs Bullet of the requested precision: fp64 in this process, fp32 through the float executable.
// `warm_step`: also time one warm step (the contacts returned are always those of the first
// detection). Throws IoError when the float executable cannot be found or run.
OracleResult bullet_collide(const OracleBodies& bodies, Precision bullet, bool warm_step = false);

// Path of `contactgrid-bullet-float` as located above; throws IoError listing where it looked.
std::string bullet_float_executable();

// This process's peak resident memory in bytes (VmHWM of /proc/self/status: its own address space;
// getrusage's ru_maxrss carries over the peak of the process that spawned it); 0 when unknown.
std::uint64_t peak_resident_bytes();

// The displacement of body `index` in the warm step: deterministic, |d| = 1e-3·radius.
Vec3<double> warm_step_displacement(std::size_t index, double radius);

// ---- inside bullet_oracle.cpp (one flavour per binary) ------------------------------------------
namespace bullet_native {
// Runs the Bullet linked into this binary (double in cg_validate, float in the float executable).
OracleResult collide(const OracleBodies& bodies, bool warm_step);
}  // namespace bullet_native

// Exchange files (bullet_exchange.cpp; used by both binaries).
void write_oracle_input(const std::string& path, const OracleBodies& bodies, bool warm_step);
OracleBodies read_oracle_input(const std::string& path, bool& warm_step);
void write_oracle_output(const std::string& path, const OracleResult& result);
OracleResult read_oracle_output(const std::string& path);

}  // namespace cg
