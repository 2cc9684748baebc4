#pragma once
// Walls of the granular dynamics, shared by both backends: static rigid surfaces a body touches with
// the same force law as another body (core/dem_contact.hpp, with the body's own radius and mass).
// Each wall is one contact slot per body (its tangential spring is kept per body and wall):
//   plane     a half-space boundary: `point` on it, `normal` the unit normal into the domain
//   cylinder  the inside of a vertical (z) cylinder: axis through `point` (x, y), `radius`
//   orifice   a horizontal plate at z = point.z with a circular hole of radius `hole` centred on
//             (point.x, point.y): material rests on it from above, falls through the hole; the hole's
//             rim is an edge (a body over the hole touches the rim circle)
// Boxes are planes: an axis-aligned box six, an open-bottom box its four sides (the command line
// builds them). A body's deepest point against a flat surface is its support (core/dem_body.hpp:
// exact for ellipsoids); the cylinder is flat where the body touches it (radius ≫ body), and an
// ellipsoid's contact with the rim is its extent towards the rim's nearest point.
#include <cstdint>

#include "core/dem_body.hpp"

namespace cg::dem {

enum class WallKind : std::uint8_t { plane, cylinder, orifice };

struct Wall {
  WallKind kind = WallKind::plane;
  Vec3<double> point{0, 0, 0};
  Vec3<double> normal{0, 0, 1};  // plane only
  double radius = 0;             // cylinder
  double hole = 0;               // orifice
};

// A body's contact with a wall: `normal` points from the wall into the body (the force on the body
// is along it), `overlap` > 0 when they touch, `point` the middle of the overlap (lever arm).
struct WallContact {
  Vec3<double> normal{0, 0, 1};
  double overlap = 0;
  Vec3<double> point{0, 0, 0};
};

// The contact of a flat surface (through `p`, unit normal `n` into the domain) with the body.
CG_HD WallContact flat_contact(const BodyShape& s, Vec3<double> p, Vec3<double> n) {
  const Vec3<double> deepest = support(s, -n);
  const double overlap = dot(p - deepest, n);
  return {n, overlap, deepest + (0.5 * overlap) * n};
}

CG_HD WallContact wall_contact(const Wall& w, const BodyShape& s) {
  switch (w.kind) {
    case WallKind::plane:
      return flat_contact(s, w.point, w.normal);
    case WallKind::cylinder: {
      const Vec3<double> rho{s.centre.x - w.point.x, s.centre.y - w.point.y, 0};
      const double r = cg_sqrt(dot(rho, rho));
      if (!(r > 0)) return {};  // on the axis: the wall is at least its radius away
      const Vec3<double> u = (1.0 / r) * rho;
      const Vec3<double> at{w.point.x + w.radius * u.x, w.point.y + w.radius * u.y, s.centre.z};
      return flat_contact(s, at, -u);
    }
    case WallKind::orifice: {
      const Vec3<double> rho{s.centre.x - w.point.x, s.centre.y - w.point.y, 0};
      const double r = cg_sqrt(dot(rho, rho));
      if (r >= w.hole) {  // over the plate (from above only: what fell through is gone)
        if (s.centre.z < w.point.z) return {};
        return flat_contact(s, Vec3<double>{s.centre.x, s.centre.y, w.point.z}, Vec3<double>{0, 0, 1});
      }
      // over the hole: the rim's nearest point (on the axis, any point of the rim is: take +x)
      const Vec3<double> u = r > 0 ? (1.0 / r) * rho : Vec3<double>{1, 0, 0};
      const Vec3<double> e{w.point.x + w.hole * u.x, w.point.y + w.hole * u.y, w.point.z};
      const Vec3<double> d = s.centre - e;
      const double dist = cg_sqrt(dot(d, d));
      if (!(dist > 0)) return {};
      const Vec3<double> n = (1.0 / dist) * d;
      const double overlap = extent(s, -n) - dist;
      return {n, overlap, e + (0.5 * overlap) * n};
    }
  }
  return {};
}

}  // namespace cg::dem
