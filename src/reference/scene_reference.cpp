// A scene's exact contacts (scene_reference.hpp): the bounding spheres' sweep proposes, the closed form
// or the ellipsoid minimisation decides.
#include "reference/scene_reference.hpp"

#include "reference/ellipsoid_reference.hpp"

namespace cg::exact {
namespace {

Body reference_body(const BodiesView& bodies, std::size_t i) {
  const Vec3<double>& c = bodies.position[i];
  const V centre{LD(c.x), LD(c.y), LD(c.z)};
  if (bodies.shape.empty() || bodies.shape[i] == Shape::sphere) {
    const LD r = bodies.radius[i];
    return make_body(centre, {r, r, r}, {1, 0, 0, 0});
  }
  const Vec3<double>& e = bodies.semi_axes[i];
  const Quat<double>& q = bodies.orientation[i];
  return make_body(centre, {LD(e.x), LD(e.y), LD(e.z)}, {LD(q.w), LD(q.x), LD(q.y), LD(q.z)});
}

bool is_sphere(const BodiesView& bodies, std::int64_t i) {
  return bodies.shape.empty() || bodies.shape[std::size_t(i)] == Shape::sphere;
}

}  // namespace

std::vector<RefContact> reference_contacts(const BodiesView& bodies, const SceneReferenceOptions& options) {
  // The bounding spheres' pairs within slack hold every pair within slack: a body lies inside its
  // bounding sphere, so h_X <= r_X, min f <= ra + rb − |a − b| and the exact distance is at least the
  // bounding spheres' distance.
  std::vector<RefContact> close = reference_contacts(bodies.position, bodies.radius, options.slack);
  if (bodies.shape.empty()) return close;
  std::vector<RefContact> out;
  out.reserve(close.size());
  for (const RefContact& c : close) {
    if (is_sphere(bodies, c.a) && is_sphere(bodies, c.b)) {
      out.push_back(c);
      continue;
    }
    Pair p{reference_body(bodies, std::size_t(c.a)), reference_body(bodies, std::size_t(c.b)), {}};
    p.r = sub(p.a.centre, p.b.centre);
    const Reference ref = exact_contact(p, options.ellipsoid_samples);
    if (ref.distance > options.slack) continue;
    RefContact e{c.a, c.b, ref.distance, {ref.n.x, ref.n.y, ref.n.z}, {}, {}};
    const V pa = ref.position_on_a, pb = ref.position_on_b;
    e.pa[0] = pa.x, e.pa[1] = pa.y, e.pa[2] = pa.z;
    e.pb[0] = pb.x, e.pb[1] = pb.y, e.pb[2] = pb.z;
    out.push_back(e);
  }
  return out;
}

}  // namespace cg::exact
