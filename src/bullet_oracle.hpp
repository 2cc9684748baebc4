#pragma once
// Bullet 3 as the oracle for sphere contacts (CONTRACT §4), behind an interface without Bullet types.
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
//   - only manifold points with distance <= 0 are reported;
//   - positions, normals and distances are Bullet's own values (btManifoldPoint positionWorldOnA/B,
//     normalWorldOnB, distance1) converted to double.
//
// Locating the float executable (bullet_float_executable()):
//   1. $CONTACTGRID_BULLET_FLOAT if set (must name an executable file);
//   2. `contactgrid-bullet-float` next to the running executable (/proc/self/exe), i.e. the install
//      layout (bin/contactgrid, bin/contactgrid-bullet-float);
//   3. the path the build tree gave it (compile definition CG_BULLET_FLOAT_BUILD_PATH), for tests.
//
// Exchange format (native endianness; both processes run on the same host):
//   input : "CGBOIN01", u64 n, u8 warm, n × {f64 x, y, z, r}, n × i64 id
//   output: "CGBOOUT1", u32 sizeof(btScalar), f64 scratch_s, f64 warm_s (-1: not run), u64 k,
//           k × {i64 id_a, i64 id_b, f64 pa[3], f64 pb[3], f64 n[3], f64 distance}
#include <cstdint>
#include <string>
#include <vector>

#include "core/vec3.hpp"
#include "engine.hpp"

namespace cg {

// Spheres handed to Bullet, in world coordinates. Invariant: ids strictly ascending.
struct OracleSpheres {
  std::vector<Vec3<double>> position;
  std::vector<double> radius;
  std::vector<std::int64_t> id;
  std::size_t size() const { return radius.size(); }
};

struct OracleResult {
  Contacts<double> contacts;   // sorted, id_a < id_b, distance <= 0
  int scalar_bytes = 8;        // sizeof(btScalar) of the Bullet that produced them (8 or 4)
  double scratch_seconds = 0;  // world construction + adding bodies + first detection
  double warm_seconds = -1;    // one warm step (move every body slightly, detect again); -1: not run
};

// Runs Bullet of the requested precision: fp64 in this process, fp32 through the float executable.
// `warm_step`: also time one warm step (the contacts returned are always those of the first
// detection). Throws IoError when the float executable cannot be found or run.
OracleResult bullet_collide(const OracleSpheres& spheres, Precision bullet, bool warm_step = false);

// Path of `contactgrid-bullet-float` as located above; throws IoError listing where it looked.
std::string bullet_float_executable();

// The displacement of body `index` in the warm step: deterministic, |d| = 1e-3·radius.
Vec3<double> warm_step_displacement(std::size_t index, double radius);

// ---- inside bullet_oracle.cpp (one flavour per binary) ------------------------------------------
namespace bullet_native {
// Runs the Bullet linked into this binary (double in cg_validate, float in the float executable).
OracleResult collide(const OracleSpheres& spheres, bool warm_step);
}  // namespace bullet_native

// Exchange files (bullet_exchange.cpp; used by both binaries).
void write_oracle_input(const std::string& path, const OracleSpheres& spheres, bool warm_step);
OracleSpheres read_oracle_input(const std::string& path, bool& warm_step);
void write_oracle_output(const std::string& path, const OracleResult& result);
OracleResult read_oracle_output(const std::string& path);

}  // namespace cg
