#pragma once
// CUDA shapes (scenes with ellipsoids; sphere-only scenes run none of this): the device-array path's
// check of the shape rows (validate_shapes' predicate, core/shape.hpp, one thread per body), the
// upload of the host arrays' shape rows and pack_shapes (a PackedShape per body, input order, read by
// the narrow stage's ShapeDecide and, in centre-cut scenes, by pack's reorder for the cut shapes; where
// the bodies keep their order reorder packs them itself). Both run inside the pack stage's timing.
#include <algorithm>
#include <cstring>
#include <string>

#include "core/shape.hpp"
#include "cuda/common.cuh"
#include "cuda/run_state.cuh"
#include "cuda/workspace.cuh"

namespace cg::cuda {

// The device-array path's shape check, in two parts that read each row once: here (before the call's
// plan, which needs the count) the kind bytes alone — c->ellipsoids += the ellipsoids, c->bad_shape =
// n - i of the first body i of no known kind (the sphere-only path packs no shapes) — grid-stride;
// the rest of validate_shapes' predicate runs in pack_shapes, which reads the rows anyway (so the rows
// are read once, BENCHMARKS.md §3). The count is summed over the warp before its one atomic: an atomic
// per thread on one address would serialise on it.
__global__ void shape_count_kernel(const Shape* __restrict__ kind, std::uint64_t n,
                                   Counters* __restrict__ c) {
  std::uint32_t ellipsoids = 0;
  for (std::uint64_t i = std::uint64_t(blockIdx.x) * kBlock + threadIdx.x; i < n;
       i += std::uint64_t(gridDim.x) * kBlock) {
    const std::uint8_t k = static_cast<std::uint8_t>(kind[i]);
    ellipsoids += k == static_cast<std::uint8_t>(Shape::ellipsoid) ? 1u : 0u;
    if (k != static_cast<std::uint8_t>(Shape::ellipsoid) && k != static_cast<std::uint8_t>(Shape::sphere))
      atomicMax(&c->bad_shape, static_cast<unsigned long long>(n - i));
  }
  const std::uint32_t warp_sum = __reduce_add_sync(0xffffffffu, ellipsoids);  // every lane is here
  if ((threadIdx.x & 31u) == 0 && warp_sum)
    atomicAdd(&c->ellipsoids, static_cast<unsigned long long>(warp_sum));
}

// The shape rows pack reads (input order) and where their packed shapes go; kind null: a scene of
// spheres alone. check (the device-array path): shape_fault() of each body as well.
template <class Real>
struct ShapeInput {
  const Shape* kind = nullptr;
  const double* semi = nullptr;
  const double* orient = nullptr;
  bool check = false;
  PackedShape<Real>* out = nullptr;
};

// pack_shape() of body i; with in.check the first bad body's n - i into c->bad_shape (read with the
// pack stage's counters).
template <class Real>
__device__ __forceinline__ PackedShape<Real> packed_shape_of(const ShapeInput<Real>& in,
                                                             const double* __restrict__ rad, std::uint32_t i,
                                                             std::uint32_t n, Counters* __restrict__ c) {
  const std::uint8_t k = static_cast<std::uint8_t>(in.kind[i]);
  const double* si = in.semi + 3 * std::uint64_t(i);
  const double* qi = in.orient + 4 * std::uint64_t(i);
  double norm;
  if (in.check && shape_fault(k, rad[i], si, qi, norm) != ShapeFault::none)
    atomicMax(&c->bad_shape, static_cast<unsigned long long>(n - i));
  return pack_shape<Real>(k, si, qi);
}

// pack_shapes: the packed shape of each body, input order (renumbered bodies; else pack's reorder
// packs them where it packs the spheres: pack.cuh).
template <class Real>
__global__ void __launch_bounds__(kBlock)
    pack_shapes_kernel(ShapeInput<Real> in, const double* __restrict__ rad, std::uint32_t n,
                       Counters* __restrict__ c) {
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  if (i >= n) return;
  in.out[i] = packed_shape_of(in, rad, i, n, c);
}

}  // namespace cg::cuda

namespace cg::detail {

// The kinds of DEVICE bodies (device_bounds): queued into the bounds stage's counters, read back with
// them (bounds_stage's `also`: one wait for both).
inline void shape_count_queue(cudaStream_t st, const DeviceBodiesView& v, cuda::Counters* d_counters) {
  const int grid = static_cast<int>(std::min<std::uint64_t>(512, cuda::blocks_for(v.count)));
  cuda::shape_count_kernel<<<grid, cuda::kBlock, 0, st>>>(v.shape, v.count, d_counters);
  CG_CUDA_CHECK_LAUNCH("shape_count");
}

// The read-back counters of shape_count_queue or of the pack stage: the number of ellipsoids, or a bad
// body's rows copied back and validate_shapes()'s InputError thrown.
inline std::size_t shape_check_result(const cuda::Counters& c, const DeviceBodiesView& v) {
  if (c.bad_shape) {
    const std::uint64_t i = v.count - c.bad_shape;
    Shape kind{};
    double r = 0, semi[3] = {}, q[4] = {};
    CG_CUDA_CHECK(cudaMemcpy(&kind, v.shape + i, sizeof(kind), cudaMemcpyDeviceToHost));
    CG_CUDA_CHECK(cudaMemcpy(&r, v.radius + i, sizeof(r), cudaMemcpyDeviceToHost));
    CG_CUDA_CHECK(cudaMemcpy(semi, v.semi_axes + 3 * i, sizeof(semi), cudaMemcpyDeviceToHost));
    CG_CUDA_CHECK(cudaMemcpy(q, v.orientation + 4 * i, sizeof(q), cudaMemcpyDeviceToHost));
    const std::int64_t id = static_cast<std::int64_t>(i);
    const Vec3<double> p{0, 0, 0}, e{semi[0], semi[1], semi[2]};
    const Quat<double> o{q[0], q[1], q[2], q[3]};
    BodiesView one{{&p, 1}, {&r, 1}, {&id, 1}, {}};
    one.shape = {&kind, 1};
    one.semi_axes = {&e, 1};
    one.orientation = {&o, 1};
    validate_shapes(one);  // throws InputError naming `id`
    throw Error("internal: the device flagged the shape of body " + std::to_string(id) + " but it is valid");
  }
  return static_cast<std::size_t>(c.ellipsoids);
}

// Scenes with ellipsoids: the shape rows on the device (host-array path: uploaded by upload_stage with
// the positions and radii, transfer.cuh) and where their
// packed shapes go (r.d_shapes); `launch`: pack them here (pack_shapes_kernel), else the caller does.
// Sphere-only scenes: nothing (r.d_shapes stays null, the input's kind null).
template <class Real, class Key, class Narrow>
cuda::ShapeInput<Narrow> shapes_stage(RunState<Real, Key, Narrow>& r, bool launch) {
  cuda::ShapeInput<Narrow> in;
  if (r.job.ellipsoids == 0 || r.n == 0) return in;
  Workspace& ws = r.ws;
  const std::uint64_t n64 = r.n64;
  if (r.device_in) {
    in.kind = r.job.device_bodies->shape;
    in.semi = r.job.device_bodies->semi_axes;
    in.orient = r.job.device_bodies->orientation;
    ws.reserve({{&ws.shapes, n64 * sizeof(PackedShape<Narrow>)}}, "pack");
  } else {
    ws.reserve({{&ws.shapes, n64 * sizeof(PackedShape<Narrow>)}}, "pack");
    in.kind = reinterpret_cast<const Shape*>(ws.shape_kind.data());
    in.semi = reinterpret_cast<const double*>(ws.shape_semi.data());
    in.orient = reinterpret_cast<const double*>(ws.shape_orient.data());
  }
  in.check = r.device_in;
  in.out = r.d_shapes = ws.shapes.span_as<PackedShape<Narrow>>(r.n).data();
  r.shape_rows = {in.semi, in.orient};  // read again by the narrow stage (fp32's pairs in fp64)
  if (launch) {
    cuda::pack_shapes_kernel<Narrow>
        <<<cuda::blocks_for(r.n), cuda::kBlock, 0, r.st>>>(in, r.d_rad, r.n, r.d_counters);
    CG_CUDA_CHECK_LAUNCH("pack_shapes");
  }
  return in;
}

// After a read of the counters that follows pack_shapes: the device rows' first bad shape, if any, as
// validate_shapes' InputError.
template <class Real, class Key, class Narrow>
void check_shapes_read(const RunState<Real, Key, Narrow>& r) {
  if (r.device_in && r.h_counters->bad_shape) shape_check_result(*r.h_counters, *r.job.device_bodies);
}

}  // namespace cg::detail
