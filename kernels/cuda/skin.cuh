#pragma once
// CUDA stage skin: candidates kept across calls (EngineOptions::skin; the rule is core/skin.hpp).
//   skin_stage        the check: max |x − x_ref|², max radius growth and whether the report mask
//                     changed, in one reduction over the bodies (block maxima, one atomicMax per block
//                     on the bits of a non-negative double); a list cut by the centre line also the
//                     largest move of a body's point (turned_motion, core/centre_cut.hpp) and whether a
//                     kind or semi-axes changed (turn_kernel); the host reads them (one
//                     synchronisation) and decides, with the same arithmetic as the CPU backend
//   keep_candidates   after a build: the ordered list and the bodies' state copied into the
//                     workspace's kept buffers (owned across calls, never aliased: workspace.cuh)
//   reuse_candidates  the kept list as the narrow stage's candidates (its flags and offsets in the
//                     call's pairs buffer)
#include <cmath>
#include <cstring>
#include <cub/block/block_reduce.cuh>

#include "core/centre_cut.hpp"
#include "core/skin.hpp"
#include "cuda/common.cuh"
#include "cuda/run_state.cuh"

namespace cg::cuda {

// Body i's motion since the reference state (ref_report read only when report is): its squared
// displacement, its radius growth (>= 0) and whether its report flag changed.
struct BodyMotion {
  double moved_sq = 0, growth = 0;
  int changed = 0;
};
__device__ __forceinline__ BodyMotion body_motion(
    const double* __restrict__ pos, const double* __restrict__ rad, const std::uint8_t* __restrict__ report,
    const double* __restrict__ ref_pos, const double* __restrict__ ref_rad,
    const std::uint8_t* __restrict__ ref_report, std::uint32_t i) {
  const std::uint64_t i3 = 3 * std::uint64_t(i);
  const double dx = pos[i3] - ref_pos[i3], dy = pos[i3 + 1] - ref_pos[i3 + 1],
               dz = pos[i3 + 2] - ref_pos[i3 + 2];
  BodyMotion m;
  m.moved_sq = dx * dx + dy * dy + dz * dz;  // the host's order (host/skin.cpp), no FMA
  const double g = rad[i] - ref_rad[i];
  m.growth = g > 0 ? g : 0;
  m.changed = report && report[i] != ref_report[i];
  return m;
}

// The block's maxima of its threads' motions into the counters (one atomicMax a block on the bits
// of a non-negative double). Every thread of the block calls it.
__device__ __forceinline__ void record_motion(const BodyMotion& m, Counters* __restrict__ c) {
  using Reduce = cub::BlockReduce<double, kBlock>;
  __shared__ typename Reduce::TempStorage tmp;
  auto larger = [](double a, double b) { return a > b ? a : b; };
  const double block_moved = Reduce(tmp).Reduce(m.moved_sq, larger);
  __syncthreads();  // tmp is reused
  const double block_growth = Reduce(tmp).Reduce(m.growth, larger);
  const int block_changed = __syncthreads_or(m.changed);
  if (threadIdx.x == 0) {
    atomicMax(&c->skin_moved_sq, static_cast<unsigned long long>(__double_as_longlong(block_moved)));
    atomicMax(&c->skin_growth, static_cast<unsigned long long>(__double_as_longlong(block_growth)));
    if (block_changed) atomicMax(&c->skin_report_changed, 1ull);
  }
}

// The shape rows of the call and of a cut list's build (DEVICE; kind 1 byte, semi-axes 3 doubles,
// orientation 4 doubles w x y z a body).
struct TurnRows {
  const Shape* kind;
  const double* semi;
  const double* orient;
  const Shape* ref_kind;
  const double* ref_semi;
  const double* ref_orient;
};

// Body i's move of a point (an ellipsoid's: turned_motion; a sphere's: its centre's) and whether its
// kind or (an ellipsoid's) semi-axes changed: the host's arithmetic (host/skin.cpp).
__device__ __forceinline__ void body_turn(const double* __restrict__ pos, const double* __restrict__ rad,
                                          const double* __restrict__ ref_pos, const TurnRows& t,
                                          std::uint32_t i, double& turned, int& changed, int& turning) {
  const std::uint64_t i3 = 3 * std::uint64_t(i), i4 = 4 * std::uint64_t(i);
  const double dx = pos[i3] - ref_pos[i3], dy = pos[i3 + 1] - ref_pos[i3 + 1],
               dz = pos[i3 + 2] - ref_pos[i3 + 2];
  const bool ellipsoid = t.kind[i] == Shape::ellipsoid;
  changed = t.kind[i] != t.ref_kind[i] ||
            (ellipsoid && !(t.semi[i3] == t.ref_semi[i3] && t.semi[i3 + 1] == t.ref_semi[i3 + 1] &&
                            t.semi[i3 + 2] == t.ref_semi[i3 + 2]));
  turned = ellipsoid ? turned_motion(dx, dy, dz, rad[i], t.orient + i4, t.ref_orient + i4)
                     : cg_sqrt(dx * dx + dy * dy + dz * dz);
  turning =
      ellipsoid && !(t.orient[i4] == t.ref_orient[i4] && t.orient[i4 + 1] == t.ref_orient[i4 + 1] &&
                     t.orient[i4 + 2] == t.ref_orient[i4 + 2] && t.orient[i4 + 3] == t.ref_orient[i4 + 3]);
}

// skin, a cut list: the block's maxima of body_turn into the counters (after motion_kernel's).
__global__ void __launch_bounds__(kBlock)
    turn_kernel(const double* __restrict__ pos, const double* __restrict__ rad,
                const double* __restrict__ ref_pos, TurnRows t, std::uint32_t n, Counters* __restrict__ c) {
  using Reduce = cub::BlockReduce<double, kBlock>;
  __shared__ typename Reduce::TempStorage tmp;
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  double turned = 0;
  int changed = 0, turning = 0;
  if (i < n) body_turn(pos, rad, ref_pos, t, i, turned, changed, turning);
  const double block_turned = Reduce(tmp).Reduce(turned, [](double a, double b) { return a > b ? a : b; });
  const int block_changed = __syncthreads_or(changed);
  const int block_turning = __syncthreads_or(turning);
  if (threadIdx.x == 0) {
    atomicMax(&c->skin_turned, static_cast<unsigned long long>(__double_as_longlong(block_turned)));
    if (block_changed) atomicMax(&c->skin_shape_changed, 1ull);
    if (block_turning) atomicMax(&c->skin_body_turned, 1ull);
  }
}

// skin: the motion of bodies [0, n) since the reference state.
__global__ void __launch_bounds__(kBlock)
    motion_kernel(const double* __restrict__ pos, const double* __restrict__ rad,
                  const std::uint8_t* __restrict__ report, const double* __restrict__ ref_pos,
                  const double* __restrict__ ref_rad, const std::uint8_t* __restrict__ ref_report,
                  std::uint32_t n, Counters* __restrict__ c) {
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  record_motion(i < n ? body_motion(pos, rad, report, ref_pos, ref_rad, ref_report, i) : BodyMotion{}, c);
}

}  // namespace cg::cuda

namespace cg::detail {

// The check's decision from the counters of a motion pass (motion_kernel's, or the cell order's
// fused check and pack): reads them (one synchronisation), records the motion in stats and the stage
// "skin", and decides with the CPU backend's arithmetic.
template <class Real, class Key, class Narrow>
bool skin_decision(RunState<Real, Key, Narrow>& r) {
  r.read_counters();
  Motion m;
  double moved_sq = 0;
  std::memcpy(&moved_sq, &r.h_counters->skin_moved_sq, sizeof(double));
  std::memcpy(&m.growth, &r.h_counters->skin_growth, sizeof(double));
  m.displacement = std::sqrt(moved_sq);
  m.report_changed = r.h_counters->skin_report_changed != 0 || (r.d_report != nullptr) != r.ws.kept_reported;
  if (r.ws.kept_cut) {  // (core/centre_cut.hpp: every point's move, rotations included)
    std::memcpy(&m.displacement, &r.h_counters->skin_turned, sizeof(double));
    m.shape_changed = r.h_counters->skin_shape_changed != 0;
    m.turned = r.h_counters->skin_body_turned != 0;
    if (m.turned) r.ws.skin_turning = true;
  }
  r.stats.skin_displacement = m.displacement;
  r.stats.skin_growth = m.growth;
  r.events.mark(EngineStage::skin, r.st);
  return skin_covers(m, r.job.skin);
}

// The call's shape rows (uploaded with the bodies, or the caller's device rows; kind null without
// ellipsoids) and the kept list's reference rows.
template <class Real, class Key, class Narrow>
cuda::TurnRows turn_rows(RunState<Real, Key, Narrow>& r) {
  Workspace& ws = r.ws;
  cuda::TurnRows t{};
  if (r.job.ellipsoids == 0) return t;
  if (r.device_in) {
    t.kind = r.job.device_bodies->shape;
    t.semi = r.job.device_bodies->semi_axes;
    t.orient = r.job.device_bodies->orientation;
  } else {
    t.kind = reinterpret_cast<const Shape*>(ws.shape_kind.data());
    t.semi = reinterpret_cast<const double*>(ws.shape_semi.data());
    t.orient = reinterpret_cast<const double*>(ws.shape_orient.data());
  }
  t.ref_kind = reinterpret_cast<const Shape*>(ws.ref_kind.data());
  t.ref_semi = reinterpret_cast<const double*>(ws.ref_semi.data());
  t.ref_orient = reinterpret_cast<const double*>(ws.ref_orient.data());
  return t;
}

// The check (EngineOptions::skin > 0 and the engine found the bodies matching the kept list's):
// true when the kept list still holds every contact. Records the motion in stats and the stage
// "skin". Before pack (which zeroes the counters again).
template <class Real, class Key, class Narrow>
bool skin_stage(RunState<Real, Key, Narrow>& r) {
  if (!(r.job.skin > 0) || !r.job.check) return false;
  Workspace& ws = r.ws;
  r.d_counters = ws.counters.span_as<cuda::Counters>(1).data();
  CG_CUDA_CHECK(cudaMemsetAsync(r.d_counters, 0, sizeof(cuda::Counters), r.st));
  const bool both_reported = r.d_report && ws.kept_reported;
  cuda::motion_kernel<<<r.nb, cuda::kBlock, 0, r.st>>>(
      r.d_pos, r.d_rad, both_reported ? r.d_report : nullptr, ws.ref_pos.span_as<double>(3 * r.n64).data(),
      ws.ref_rad.span_as<double>(r.n64).data(),
      both_reported ? ws.ref_report.span_as<std::uint8_t>(r.n64).data() : nullptr, r.n, r.d_counters);
  CG_CUDA_CHECK_LAUNCH("motion");
  if (ws.kept_cut && r.n > 0) {
    const cuda::TurnRows rows = turn_rows(r);
    if (rows.kind == nullptr) {  // (no shape rows now: plan_skin checks only bodies of the same shapes)
      const unsigned long long one = 1;
      CG_CUDA_CHECK(cudaMemcpyAsync(&r.d_counters->skin_shape_changed, &one, sizeof(one),
                                    cudaMemcpyHostToDevice, r.st));
      CG_CUDA_CHECK(cudaStreamSynchronize(r.st));
    } else {
      cuda::turn_kernel<<<r.nb, cuda::kBlock, 0, r.st>>>(
          r.d_pos, r.d_rad, ws.ref_pos.span_as<double>(3 * r.n64).data(), rows, r.n, r.d_counters);
      CG_CUDA_CHECK_LAUNCH("turn");
    }
  }
  return skin_decision(r);
}

// A build's kept list: the state of the bodies it was built from (for the next call's check, and
// whether a report mask was given), its count and the distance between its a and b arrays. The
// caller has put the list in ws.kept_pairs. Both orders' builds (keep_candidates, keep_cell_candidates).
template <class Real, class Key, class Narrow>
void keep_reference(RunState<Real, Key, Narrow>& r, std::size_t stride, bool cell_order) {
  Workspace& ws = r.ws;
  const std::size_t n = r.n64;
  ws.reserve({{&ws.ref_pos, n * sizeof(Vec3<double>)},
              {&ws.ref_rad, n * sizeof(double)},
              {&ws.ref_report, r.d_report ? n : 0}},
             "skin");
  cuda::device_copy(ws.ref_pos.data(), r.d_pos, n * sizeof(Vec3<double>), r.st);
  cuda::device_copy(ws.ref_rad.data(), r.d_rad, n * sizeof(double), r.st);
  if (r.d_report) cuda::device_copy(ws.ref_report.data(), r.d_report, n, r.st);
  ws.kept_count = r.np;
  ws.kept_stride = stride;
  ws.kept_reported = r.d_report != nullptr;
  ws.kept_cell_order = cell_order;
  // a list cut by the centre line: the shape rows too (its check counts turns, core/centre_cut.hpp)
  ws.kept_cut = r.filter == CandidateFilter::centre_cut;
  if (ws.kept_cut && n > 0) {
    const cuda::TurnRows t = turn_rows(r);
    ws.reserve({{&ws.ref_kind, n * sizeof(Shape)},
                {&ws.ref_semi, n * sizeof(Vec3<double>)},
                {&ws.ref_orient, n * sizeof(Quat<double>)}},
               "skin");
    cuda::device_copy(ws.ref_kind.data(), t.kind, n * sizeof(Shape), r.st);
    cuda::device_copy(ws.ref_semi.data(), t.semi, n * sizeof(Vec3<double>), r.st);
    cuda::device_copy(ws.ref_orient.data(), t.orient, n * sizeof(Quat<double>), r.st);
  }
}

// After the order stage of a build with a skin: the list and the state it was built from, kept.
// Timed with the order stage.
template <class Real, class Key, class Narrow>
void keep_candidates(RunState<Real, Key, Narrow>& r) {
  Workspace& ws = r.ws;
  const std::size_t np = r.np;
  ws.reserve({{&ws.kept_pairs, 2 * np * sizeof(std::uint32_t)}}, "skin");
  std::uint32_t* kept = ws.kept_pairs.span_as<std::uint32_t>(2 * np).data();
  cuda::device_copy(kept, r.pair_a.Current(), np * sizeof(std::uint32_t), r.st);
  cuda::device_copy(kept + np, r.pair_b.Current(), np * sizeof(std::uint32_t), r.st);
  keep_reference(r, np, false);
  r.events.mark(EngineStage::order, r.st);
}

// The reuse: the kept list as the candidates (Current; the narrow stage's accept flags and offsets
// in the Alternate halves, the call's pairs buffer), and the contact rows' room.
template <class Real, class Key, class Narrow>
void reuse_candidates(RunState<Real, Key, Narrow>& r) {
  Workspace& ws = r.ws;
  r.np = ws.kept_count;
  const std::size_t np = r.np;
  const bool scratch = !ws.kept_cell_order;  // (the cell-order narrow reads Current() alone)
  ws.reserve({{&ws.pairs, scratch ? 2 * np * sizeof(std::uint32_t) : 0}, {&ws.out, r.out_bytes_for(np)}},
             "skin");
  std::uint32_t* kept = ws.kept_pairs.span_as<std::uint32_t>(ws.kept_stride + np).data();
  std::uint32_t* alt = scratch ? ws.pairs.span_as<std::uint32_t>(2 * np).data() : kept;
  r.pair_a = cub::DoubleBuffer<std::uint32_t>(kept, alt);
  r.pair_b =
      cub::DoubleBuffer<std::uint32_t>(kept + ws.kept_stride, scratch ? alt + np : kept + ws.kept_stride);
}

}  // namespace cg::detail
