#pragma once
// An ellipsoid for Bullet 3: a convex shape whose support function is the ellipsoid's exact one.
// Included by bullet_oracle.cpp only (it needs Bullet's headers, in whichever flavour that file is
// compiled against).
//
// In its body frame the ellipsoid with semi-axes D = diag(a, b, c) has the support point
//     s(v) = D² v / |D v|        (world: R D² Rᵀ u / |D Rᵀ u|, R from the body's transform).
// Bullet's convex algorithms (GJK, EPA) work on a margin-free core and add a sphere of the margin m
// around it: the full shape is core ⊕ ball(m), its support s_core(v) + m·v/|v|. The core here is the
// inner parallel body of the ellipsoid, s_core(v) = s(v) − m·v/|v|, so the full shape Bullet collides
// is exactly the ellipsoid. That core is convex (and its support well defined) while m stays below
// the ellipsoid's smallest radius of curvature c_min² / a_max; the constructor takes half of that when
// kEllipsoidMargin is larger. A scaled btMultiSphereShape is not an ellipsoid (its support is wrong
// by up to 16 % of pairs outside 0.1 / 10°, issue #12), which is why this class exists.
#include <btBulletCollisionCommon.h>

#include <algorithm>
#include <cmath>

namespace cg::bullet_native {

class EllipsoidShape : public btConvexInternalShape {
 public:
  // semi-axes along the body's local x, y, z (all > 0); `margin` as above.
  EllipsoidShape(btScalar a, btScalar b, btScalar c, btScalar margin) : m_semi(a, b, c) {
    m_shapeType = CUSTOM_CONVEX_SHAPE_TYPE;
    const btScalar lo = std::min({a, b, c}), hi = std::max({a, b, c});
    setMargin(std::min(margin, btScalar(0.5) * lo * lo / hi));
    m_implicitShapeDimensions = m_semi;
  }

  // The ellipsoid's support point minus the margin along v (v need not be unit; v = 0 gives a pole).
  btVector3 localGetSupportingVertexWithoutMargin(const btVector3& v) const override {
    const btVector3 dv = m_semi * v;
    const btScalar h = dv.length(), len = v.length();
    if (!(h > btScalar(0)) || !(len > btScalar(0))) return btVector3(m_semi.x() - getMargin(), 0, 0);
    return (m_semi * dv) / h - v * (getMargin() / len);
  }
  // The full support (core + margin): the ellipsoid's own support point.
  btVector3 localGetSupportingVertex(const btVector3& v) const override {
    const btVector3 dv = m_semi * v;
    const btScalar h = dv.length();
    if (!(h > btScalar(0))) return btVector3(m_semi.x(), 0, 0);
    return (m_semi * dv) / h;
  }
  void batchedUnitVectorGetSupportingVertexWithoutMargin(const btVector3* vectors, btVector3* out,
                                                         int count) const override {
    for (int i = 0; i < count; ++i) out[i] = localGetSupportingVertexWithoutMargin(vectors[i]);
  }

  // The world box of the ellipsoid: half-extent along world axis k is |row k of R D| (exact).
  void getAabb(const btTransform& t, btVector3& lo, btVector3& hi) const override {
    const btMatrix3x3& r = t.getBasis();
    btVector3 half;
    for (int k = 0; k < 3; ++k) half[k] = (r.getRow(k) * m_semi).length();
    lo = t.getOrigin() - half;
    hi = t.getOrigin() + half;
  }
  // A solid ellipsoid: I = m/5 (b² + c², a² + c², a² + b²).
  void calculateLocalInertia(btScalar mass, btVector3& inertia) const override {
    const btVector3 s2 = m_semi * m_semi;
    inertia = (mass / btScalar(5)) * btVector3(s2.y() + s2.z(), s2.x() + s2.z(), s2.x() + s2.y());
  }
  const char* getName() const override { return "contactgrid::Ellipsoid"; }

 private:
  btVector3 m_semi;
};

}  // namespace cg::bullet_native
