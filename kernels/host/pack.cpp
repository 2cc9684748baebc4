// Host stage pack: world (double) → local frame Real spheres (radius + g.radius_margin: mixed's
// enlarged spheres); per body its cells and control byte, or for the cell sort its block key (see
// stages.hpp).
#include "host/stages.hpp"

namespace cg::detail::host {
namespace {
// Body i in the local frame: Real(world − origin), its radius Real(r) + g.radius_margin.
template <class Real>
Sphere<Real> local_sphere(const BodiesView& bodies, const Vec3<double>& origin, const GridParams<Real>& g,
                          std::size_t i) {
  const Vec3<double> p = bodies.position[i];
  return {static_cast<Real>(p.x - origin.x), static_cast<Real>(p.y - origin.y),
          static_cast<Real>(p.z - origin.z), static_cast<Real>(bodies.radius[i]) + g.radius_margin};
}

// Body i's world row: its input doubles, centre and radius together.
inline Sphere<double> world_row(const BodiesView& bodies, std::size_t i) {
  const Vec3<double> p = bodies.position[i];
  return {p.x, p.y, p.z, bodies.radius[i]};
}
}  // namespace

template <class Real>
void pack(const BodiesView& bodies, const Vec3<double>& origin, const GridParams<Real>& g, Real inflation,
          bool cells_too, int threads, PackedBodies<Real>& out, Array<Sphere<double>>* world, bool blocks) {
  const std::size_t n = bodies.size();
  out.spheres.resize(n);
  out.inflation = inflation;
  Sphere<double>* w = nullptr;
  if (world != nullptr) {
    world->resize(n);
    w = world->data();
  }
  if (!cells_too) {
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
    for (std::size_t i = 0; i < n; ++i) {
      out.spheres[i] = local_sphere<Real>(bodies, origin, g, i);
      if (w) w[i] = world_row(bodies, i);
    }
    return;
  }
  out.count = {};  // fill_entries takes each body's entry count from its control byte
  if (blocks) {    // the cell sort's keys alone (block_key: super-cell and control byte)
    out.block.resize(n);
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
    for (std::size_t i = 0; i < n; ++i) {
      const Sphere<Real> s = local_sphere<Real>(bodies, origin, g, i);
      out.spheres[i] = s;
      if (w) w[i] = world_row(bodies, i);
      out.block[i] = (std::uint64_t(i) << 32) |
                     block_key(body_cells(Sphere<Real>{s.x, s.y, s.z, s.r + inflation}, g), g);
    }
    return;
  }
  out.cells.resize(n);
  out.ctrl.resize(n);
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    const Sphere<Real> s = local_sphere<Real>(bodies, origin, g, i);
    out.spheres[i] = s;
    if (w) w[i] = world_row(bodies, i);
    out.cells[i] = body_cells(Sphere<Real>{s.x, s.y, s.z, s.r + inflation}, g);
    out.ctrl[i] = control_bits(out.cells[i]);
  }
}

template <class Real>
void pack_shapes(const BodiesView& bodies, int threads, std::vector<PackedShape<Real>>& out) {
  const std::size_t n = bodies.size();
  out.resize(n);
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3<double> e = bodies.semi_axes[i];
    const Quat<double> q = bodies.orientation[i];
    const double semi[3] = {e.x, e.y, e.z}, quat[4] = {q.w, q.x, q.y, q.z};
    out[i] = pack_shape<Real>(static_cast<std::uint8_t>(bodies.shape[i]), semi, quat);
  }
}

template <class Packed>
void cut_shapes(const std::vector<PackedShape<Packed>>& shapes, int threads, Array<CutShape>& out) {
  const std::size_t n = shapes.size();
  out.resize(n);
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) out[i] = cut_shape(shapes[i]);
}

// The cells and control byte of every packed sphere (its inflated sphere), the cells by
// cells_of(sphere, i).
template <class Real, class CellsOf>
void fill_cells(int threads, PackedBodies<Real>& out, const CellsOf& cells_of) {
  const std::size_t n = out.spheres.size();
  out.cells.resize(n);
  out.ctrl.resize(n);
  out.count = {};
#pragma omp parallel for num_threads(threads) schedule(static) if (n > k_parallel_min)
  for (std::size_t i = 0; i < n; ++i) {
    const Sphere<Real> s = out.spheres[i];
    out.cells[i] = cells_of(Sphere<Real>{s.x, s.y, s.z, s.r + out.inflation}, i);
    out.ctrl[i] = control_bits(out.cells[i]);
  }
}

template <class Real>
void shape_cells(const GridParams<Real>& g, int threads, PackedBodies<Real>& out) {
  fill_cells(threads, out, [&](const Sphere<Real>& s, std::size_t i) { return cut_cells(s, out.cut[i], g); });
}

template <class Real>
void sphere_cells(const GridParams<Real>& g, int threads, PackedBodies<Real>& out) {
  fill_cells(threads, out, [&](const Sphere<Real>& s, std::size_t) { return body_cells(s, g); });
}

template void sphere_cells(const GridParams<float>&, int, PackedBodies<float>&);
template void sphere_cells(const GridParams<double>&, int, PackedBodies<double>&);
template void shape_cells(const GridParams<float>&, int, PackedBodies<float>&);
template void shape_cells(const GridParams<double>&, int, PackedBodies<double>&);
template void cut_shapes(const std::vector<PackedShape<float>>&, int, Array<CutShape>&);
template void cut_shapes(const std::vector<PackedShape<double>>&, int, Array<CutShape>&);
template void pack_shapes(const BodiesView&, int, std::vector<PackedShape<float>>&);
template void pack_shapes(const BodiesView&, int, std::vector<PackedShape<double>>&);

template void pack(const BodiesView&, const Vec3<double>&, const GridParams<float>&, float, bool, int,
                   PackedBodies<float>&, Array<Sphere<double>>*, bool);
template void pack(const BodiesView&, const Vec3<double>&, const GridParams<double>&, double, bool, int,
                   PackedBodies<double>&, Array<Sphere<double>>*, bool);

}  // namespace cg::detail::host
