#pragma once
// Candidates kept across calls (EngineOptions::skin, a Verlet skin): the rule that decides whether a
// kept candidate list still holds every contact, shared by both backends (g++-safe, host only).
//
// A list is built from bounding spheres inflated by `inflation` = skin/2 + a rounding margin each
// (so every pair with |a − b| <= r_a + r_b + skin is a candidate). At a later call, with d the largest
// displacement of a centre since the build and g the largest radius growth, a pair in contact now
// had |a − b| <= r_a + r_b + 2(d + g) at the build: the list still covers it when 2(d + g) <= skin.
//
// Rounding. The pair test runs in Real on local coordinates of magnitude <= C (the bounds' distance
// from the origin); its error on a distance is below 4·eps·(C + r_a + r_b + skin) at the build and at
// the later call. The margin 16·eps·(C + 2 r_max + 2 skin) per radius (32·eps… per pair) covers both,
// where C is the build's coordinate bound plus the skin; a later call whose bound exceeds that
// (a far-away explicit frame) rebuilds. The displacement is measured in double (relative error a few
// double ulps, far inside the margin).
//
// Scenes of the centre cut (core/narrow.hpp: scene_filter) cut the list with the skin as the cut's
// margin (core/centre_cut.hpp): then d is the largest move of any point of a body (its centre's and
// its rotation's, turned_motion), and a change of a body's kind or semi-axes rebuilds.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>

namespace cg {

// What moved since the candidates were built (the skin check's reduction).
struct Motion {
  double displacement = 0;      // max |x_i − x_i,ref|
  double growth = 0;            // max(0, max r_i − r_i,ref)
  bool report_changed = false;  // the report mask differs from the build's
  bool shape_changed = false;   // a cut list: some body's kind or semi-axes differ from the build's
  bool turned = false;          // a cut list: some ellipsoid's orientation differs from the build's
};

// True when a list built with `skin` still holds every contact.
inline bool skin_covers(const Motion& m, double skin) {
  return !m.report_changed && !m.shape_changed && 2 * (m.displacement + m.growth) <= skin;
}

// Whether a skin's list is cut by the centre line in the scenes of the centre cut (scene_filter):
// CONTACTGRID_SKIN_CUT=0 keeps every pair of inflated bounding spheres (the former list; the same rows).
inline bool skin_cut_enabled() {
  const char* v = std::getenv("CONTACTGRID_SKIN_CUT");
  return v == nullptr || std::strcmp(v, "0") != 0;
}

// Whether this build cuts its list (in the scenes of the centre cut): while no check of a cut list has
// seen a body turn (`turning`, kept by the engine across calls). A cut list lasts while every point of
// a body moves less than skin/2, turns included; the bounding spheres' list ignores turns. Where the
// bodies turn as they move (a granular flow: simulate), the cut list is rebuilt every step or two and
// the bounding spheres' list pays (2^22 settled ellipsoids on an H200: 77.4 steps/s cut, 92.8 not,
// BENCHMARKS.md §34); where they only move (`detect --drift`) the cut's fewer candidates pay. The
// decision follows each call's check, so both backends build the same list at the same call.
inline bool skin_cut_wanted(bool turning) { return skin_cut_enabled() && !turning; }

// The radius inflation of the candidate filter for a list built with `skin` (see the file comment):
// `coordinate_bound` is the call's largest local coordinate magnitude plus the skin, `r_max` the
// largest radius, `real_epsilon` the machine epsilon of the run's real type.
inline double skin_inflation(double skin, double coordinate_bound, double r_max, double real_epsilon) {
  return 0.5 * skin + 16 * real_epsilon * (coordinate_bound + 2 * r_max + 2 * skin);
}

}  // namespace cg
