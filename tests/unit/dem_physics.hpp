#pragma once
// The granular-dynamics tests' shared pieces (test_dem.cpp: the physics against analytic solutions,
// test_dem_backends.cpp: CPU = CUDA bit for bit): a plane wall, and the typed fixture of the physics
// cases (in a named namespace: its tests are in both files, and GoogleTest wants one fixture class per
// suite).
#include <gtest/gtest.h>

#include "backends.hpp"
#include "dem.hpp"

namespace cg::test {

using dem::Wall;
using dem::WallKind;

inline Wall plane(Vec3<double> point, Vec3<double> normal) {
  Wall w;
  w.kind = WallKind::plane;
  w.point = point;
  w.normal = normal;
  return w;
}

// The physics cases: one test body per backend (CUDA skips, visibly, without a GPU).
template <class B>
class DemPhysics : public ::testing::Test {
 protected:
  void SetUp() override { CG_SKIP_WITHOUT_BACKEND(B); }
};

}  // namespace cg::test
