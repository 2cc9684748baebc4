#pragma once
// CUDA stage narrow: narrow_decide() (kernels/core/narrow.hpp) on each ordered candidate pair and the
// contact rows of the requested fields, world frame, laid out in ws.out (16-byte aligned fields).
// The pair stage's filter here is spheres_touch, so every candidate is a contact
// (narrow_may_reject() false) and each candidate's row is written at its own index: no scan. A
// rejecting filter (an ellipsoid broad phase, a candidate list kept across calls) needs the
// count → scan → fill of the CPU backend's narrow (kernels/host/narrow.cpp), not yet on the GPU.
#include "core/narrow.hpp"
#include "cuda/common.cuh"
#include "cuda/run_state.cuh"

namespace cg::cuda {

// narrow: contact data of each sorted pair, world frame as the host: Real(double(origin) + double(v)).
template <class Real>
__global__ void __launch_bounds__(kBlock)
    narrow_kernel(const std::uint32_t* __restrict__ pair_a, const std::uint32_t* __restrict__ pair_b,
                  std::uint32_t n_pairs, const Sphere<Real>* __restrict__ spheres, Vec3<double> origin,
                  ContactPtrs<Real> out, bool full) {
  const std::uint32_t k = blockIdx.x * kBlock + threadIdx.x;
  if (k >= n_pairs) return;
  const std::uint32_t a = pair_a[k], b = pair_b[k];
  const Sphere<Real> sa = spheres[a], sb = spheres[b];
  const ContactRow<Real> row = narrow_decide(sa, sb, origin, full).row;  // core/narrow.hpp
  out.id_a[k] = a;
  out.id_b[k] = b;
  out.position_on_a[k] = row.position_on_a;
  out.position_on_b[k] = row.position_on_b;
  out.normal_on_b[k] = row.normal_on_b;
  out.distance[k] = row.distance;
  if (full) {
    out.local_point_a[k] = row.local_point_a;
    out.local_point_b[k] = row.local_point_b;
    out.dir1[k] = row.lateral_friction_dir1;
    out.dir2[k] = row.lateral_friction_dir2;
  }
}

}  // namespace cg::cuda

namespace cg::detail {

// The contact arrays of `rows` rows in the workspace's out buffer; returns their bytes.
template <class Real>
std::size_t layout_contacts(std::byte* o, std::size_t rows, bool full, cuda::ContactPtrs<Real>& cp) {
  const std::size_t v3 = cuda::align16(rows * sizeof(Vec3<Real>));
  const std::size_t ids = cuda::align16(rows * sizeof(std::int64_t));
  const std::size_t reals = cuda::align16(rows * sizeof(Real));
  std::size_t at = 0;
  auto take = [&](std::size_t bytes) {
    std::byte* p = o + at;
    at += bytes;
    return p;
  };
  cp = {};
  cp.id_a = reinterpret_cast<std::int64_t*>(take(ids));
  cp.id_b = reinterpret_cast<std::int64_t*>(take(ids));
  cp.position_on_a = reinterpret_cast<Vec3<Real>*>(take(v3));
  cp.position_on_b = reinterpret_cast<Vec3<Real>*>(take(v3));
  cp.normal_on_b = reinterpret_cast<Vec3<Real>*>(take(v3));
  cp.distance = reinterpret_cast<Real*>(take(reals));
  if (full) {
    cp.local_point_a = reinterpret_cast<Vec3<Real>*>(take(v3));
    cp.local_point_b = reinterpret_cast<Vec3<Real>*>(take(v3));
    cp.dir1 = reinterpret_cast<Vec3<Real>*>(take(v3));
    cp.dir2 = reinterpret_cast<Vec3<Real>*>(take(v3));
  }
  return at;
}

template <class Real, class Key>
void narrow_stage(RunState<Real, Key>& r) {
  if (narrow_may_reject(r.filter)) throw Error("internal: the CUDA narrow stage has no rejecting path yet");
  r.n_rows = r.np;
  r.out_bytes = layout_contacts(r.ws.out.data(), r.n_rows, r.full, r.cp);
  if (r.np > 0) {
    cuda::narrow_kernel<Real><<<cuda::blocks_for(r.np), cuda::kBlock, 0, r.st>>>(
        r.pair_a.Current(), r.pair_b.Current(), r.np, r.d_spheres, r.origin, r.cp, r.full);
    CG_CUDA_CHECK_LAUNCH("narrow");
  }
  r.events.mark(Stage::narrow, r.st);
}

}  // namespace cg::detail
