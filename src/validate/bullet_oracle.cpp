// The Bullet side of the oracle (see bullet_oracle.hpp). This one source is compiled once per Bullet
// flavour: against double Bullet into cg_validate, and against float Bullet, with
// CG_BULLET_ORACLE_MAIN defined, into the executable `contactgrid-bullet-float`. Nothing here may
// depend on which flavour it is, except through btScalar.
//
// Invariants: bodies are added in id order, each at (centre − origin) · scale with its lengths · scale
// (Bullet's frame, bullet_oracle.hpp; Bullet's body A, the first added, is the smaller id); one
// performDiscreteCollisionDetection() gives the contacts; the world is torn down in O(pairs + n) (Bullet's
// own teardown removes each proxy by scanning every pair: O(n · pairs), minutes at 2^20).
#include "validate/bullet_oracle.hpp"

#include <btBulletCollisionCommon.h>

#include <algorithm>
#include <cstdio>
#include <memory>
#include <numeric>
#include <string>
#include <vector>

#include "errors.hpp"
#include "timing.hpp"
#include "validate/bullet_ellipsoid_shape.hpp"

namespace cg::bullet_native {
namespace {

btVector3 to_bt(const Vec3<double>& v) { return btVector3(btScalar(v.x), btScalar(v.y), btScalar(v.z)); }
Vec3<double> from_bt(const btVector3& v) { return {double(v.x()), double(v.y()), double(v.z())}; }

// Removes every overlapping pair (releasing its algorithm and manifold) in one pass, so that the
// world's destructor finds an empty pair cache and destroys each proxy in O(log n).
struct RemoveAllPairs : btOverlapCallback {
  bool processOverlap(btBroadphasePair&) override { return true; }
};

// One Bullet collision world over the bodies. Members are declared in destruction-safe order:
// shapes and objects outlive the world that points at them.
class BulletWorld {
 public:
  explicit BulletWorld(const OracleBodies& s)
      : m_dispatcher(&m_config), m_world(&m_dispatcher, &m_broadphase, &m_config) {
    const std::size_t n = s.size();
    m_shapes.reserve(n);
    m_objects.reserve(n);
    for (std::size_t i = 0; i < n; ++i) {
      if (s.is_ellipsoid(i)) {
        const Vec3<double> e = s.scale * s.semi_axes[i];
        m_shapes.push_back(std::make_unique<EllipsoidShape>(btScalar(e.x), btScalar(e.y), btScalar(e.z),
                                                            btScalar(kEllipsoidMargin)));
      } else {
        m_shapes.push_back(std::make_unique<btSphereShape>(btScalar(s.scale * s.radius[i])));
      }
      m_objects.push_back(std::make_unique<btCollisionObject>());
      m_objects.back()->setWorldTransform(transform(s, i, s.position[i]));
      m_objects.back()->setCollisionShape(m_shapes.back().get());
      // Partners (a piece's margin) are never paired with each other: group 2 collides with group 1 only.
      const bool partner = !s.partner.empty() && s.partner[i] != 0;
      m_world.addCollisionObject(m_objects.back().get(), partner ? 2 : 1, partner ? 1 : -1);  // index == i
    }
  }
  ~BulletWorld() {
    RemoveAllPairs remove_all;
    m_broadphase.getOverlappingPairCache()->processAllOverlappingPairs(&remove_all, &m_dispatcher);
  }
  BulletWorld(const BulletWorld&) = delete;
  BulletWorld& operator=(const BulletWorld&) = delete;

  void collide() { m_world.performDiscreteCollisionDetection(); }
  std::uint64_t pairs() {
    return std::uint64_t(m_broadphase.getOverlappingPairCache()->getNumOverlappingPairs());
  }

  void move_all(const OracleBodies& s) {
    for (std::size_t i = 0; i < m_objects.size(); ++i)
      m_objects[i]->setWorldTransform(
          transform(s, i, s.position[i] + warm_step_displacement(i, s.radius[i])));
  }

  // Deepest manifold point of every pair with distance <= 0, as (id_a < id_b), sorted.
  Contacts<double> contacts(const OracleBodies& s) {
    struct Row {
      std::int64_t a, b;
      Vec3<double> pa, pb, n;
      double d;
    };
    std::vector<Row> rows;
    const int manifolds = m_dispatcher.getNumManifolds();
    rows.reserve(std::size_t(manifolds));
    for (int m = 0; m < manifolds; ++m) {
      const btPersistentManifold* pm = m_dispatcher.getManifoldByIndexInternal(m);
      int best = -1;
      for (int c = 0; c < pm->getNumContacts(); ++c) {
        const btManifoldPoint& p = pm->getContactPoint(c);
        if (p.getDistance() <= btScalar(0) &&
            (best < 0 || p.getDistance() < pm->getContactPoint(best).getDistance()))
          best = c;
      }
      if (best < 0) continue;
      const btManifoldPoint& p = pm->getContactPoint(best);
      const double to_scene = 1 / s.scale;  // exact: the scale is a power of two
      Row r{s.id[std::size_t(pm->getBody0()->getWorldArrayIndex())],
            s.id[std::size_t(pm->getBody1()->getWorldArrayIndex())],
            to_scene * from_bt(p.getPositionWorldOnA()) + s.origin,
            to_scene * from_bt(p.getPositionWorldOnB()) + s.origin,
            from_bt(p.m_normalWorldOnB),
            to_scene * double(p.getDistance())};
      if (r.a > r.b) {  // express the contact with A = the smaller id
        std::swap(r.a, r.b);
        std::swap(r.pa, r.pb);
        r.n = -r.n;
      }
      rows.push_back(r);
    }
    std::sort(rows.begin(), rows.end(),
              [](const Row& x, const Row& y) { return x.a != y.a ? x.a < y.a : x.b < y.b; });
    Contacts<double> out;
    for (const Row& r : rows) {
      out.id_a.push_back(r.a);
      out.id_b.push_back(r.b);
      out.position_on_a.push_back(r.pa);
      out.position_on_b.push_back(r.pb);
      out.normal_on_b.push_back(r.n);
      out.distance.push_back(r.d);
    }
    return out;
  }

 private:
  // Body i at `centre` (scene), in Bullet's frame, rotated by its quaternion.
  static btTransform transform(const OracleBodies& s, std::size_t i, Vec3<double> centre) {
    btTransform t;
    t.setIdentity();
    t.setOrigin(to_bt(s.scale * (centre - s.origin)));
    if (s.is_ellipsoid(i)) {
      const auto& q = s.orientation[i];  // (w, x, y, z); btQuaternion takes (x, y, z, w)
      const btQuaternion r{btScalar(q[1]), btScalar(q[2]), btScalar(q[3]), btScalar(q[0])};
      t.setRotation(r.normalized());
    }
    return t;
  }

  std::vector<std::unique_ptr<btConvexShape>> m_shapes;
  std::vector<std::unique_ptr<btCollisionObject>> m_objects;
  btDefaultCollisionConfiguration m_config;
  btCollisionDispatcher m_dispatcher;
  btDbvtBroadphase m_broadphase;
  btCollisionWorld m_world;
};

}  // namespace

OracleResult collide(const OracleBodies& bodies, bool warm_step) {
  for (std::size_t i = 1; i < bodies.size(); ++i)
    if (bodies.id[i - 1] >= bodies.id[i])
      throw InputError("Bullet oracle: body ids must be strictly ascending (row " + std::to_string(i) + ")");
  OracleResult result;
  result.scalar_bytes = int(sizeof(btScalar));
  const auto t0 = WallClock::now();
  BulletWorld world(bodies);
  world.collide();
  result.scratch_seconds = seconds_since(t0);
  result.pairs = world.pairs();
  result.contacts = world.contacts(bodies);
  if (warm_step) {
    const auto t1 = WallClock::now();
    world.move_all(bodies);
    world.collide();
    result.warm_seconds = seconds_since(t1);
  }
  return result;
}

}  // namespace cg::bullet_native

#ifdef CG_BULLET_ORACLE_MAIN
// contactgrid-bullet-float INPUT OUTPUT: runs this binary's Bullet on INPUT, writes OUTPUT.
// Exit codes as errors.hpp: 0 ok, 2 usage, 3 input, 6 I/O, 8 internal.
int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr,
                 "usage: %s INPUT OUTPUT\n"
                 "Runs Bullet (%s precision) on the bodies of INPUT (contactgrid's oracle exchange\n"
                 "format, see src/validate/bullet_oracle.hpp) and writes the contacts to OUTPUT.\n"
                 "Started by `contactgrid validate --bullet float`; not meant to be run by hand.\n",
                 argv[0], sizeof(btScalar) == 8 ? "double" : "single");
    return 2;
  }
  try {
    bool warm = false;
    const cg::OracleBodies bodies = cg::read_oracle_input(argv[1], warm);
    cg::write_oracle_output(argv[2], cg::bullet_native::collide(bodies, warm));
    return 0;
  } catch (const cg::Error& e) {
    std::fprintf(stderr, "%s: %s\n", argv[0], e.what());
    return e.exit_code();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: internal error: %s\n", argv[0], e.what());
    return 8;
  }
}
#endif
