#pragma once
// The CUDA backend's resident bodies (Engine::set_resident and the calls on them): their upload and
// splice, the view and copies of their rows, the mark and extent of a step loop, and a halo's row
// lists (gather, scatter, copy between engines, rows outside an interval). Apart from the class
// (backend_class.cuh) as calls of the engine's API on it; included once, by cuda_backend.cu (one
// translation unit).
#include <thrust/iterator/counting_iterator.h>

#include <algorithm>
#include <cstdint>
#include <cub/device/device_select.cuh>
#include <span>
#include <vector>

#include "cuda/backend_class.cuh"
#include "cuda/resident_extent.cuh"
#include "cuda/resident_rows.cuh"
#include "cuda/splice.cuh"
#include "cuda/transfer.cuh"

namespace cg::detail {

namespace {
// Host ranges into the resident DEVICE arrays, by Tuning::upload as the upload stage chooses
// (streamed through the pinned ring from 1 MiB: the host threads fill its slots while the copy engine
// moves the previous one; else pageable copies), then the stream's end.
void upload_resident(CudaBackend& b, const std::vector<HostDevice>& ranges) {
  std::size_t total = 0;
  for (const HostDevice& h : ranges) total += h.bytes;
  if (upload_transfer(b.m_tuning, total) == HostTransfer::streamed) {
    streamed_upload(cuda::pinned_ring(b.m_device), b.m_tuning.transfer_slot_bytes, ranges, b.m_stream);
  } else {
    for (const HostDevice& h : ranges)
      if (h.bytes > 0)
        CG_CUDA_CHECK(cudaMemcpyAsync(h.device, h.host, h.bytes, cudaMemcpyHostToDevice, b.m_stream));
  }
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

HostDevice host_device(void* device, const void* host, std::size_t bytes) {
  return {static_cast<std::byte*>(const_cast<void*>(host)), static_cast<std::byte*>(device), bytes};
}
}  // namespace

void resident_upload(CudaBackend& b, const BodiesView& bodies) {
  const std::size_t n = bodies.size();
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  b.refresh_tuning();
  Workspace& ws = b.m_ws;
  const bool shapes = !bodies.shape.empty();
  ws.reserve({{&ws.res_pos, n * sizeof(Vec3<double>)},
              {&ws.res_rad, n * sizeof(double)},
              {&ws.res_report, bodies.report.empty() ? 0 : n},
              {&ws.res_shape, shapes ? n * sizeof(Shape) : 0},
              {&ws.res_semi, shapes ? n * sizeof(Vec3<double>) : 0},
              {&ws.res_orient, shapes ? n * sizeof(Quat<double>) : 0},
              {&ws.res_id, bodies.id.empty() ? 0 : n * sizeof(std::int64_t)}},
             "resident bodies");
  ws.res_count = n;
  ws.res_ided = !bodies.id.empty();
  ws.res_reported = !bodies.report.empty();
  ws.res_shaped = shapes;
  if (n == 0) return;
  std::vector<HostDevice> ranges{
      host_device(ws.res_pos.data(), bodies.position.data(), n * sizeof(Vec3<double>)),
      host_device(ws.res_rad.data(), bodies.radius.data(), n * sizeof(double))};
  if (!bodies.report.empty()) ranges.push_back(host_device(ws.res_report.data(), bodies.report.data(), n));
  if (!bodies.id.empty())
    ranges.push_back(host_device(ws.res_id.data(), bodies.id.data(), n * sizeof(std::int64_t)));
  if (shapes) {
    ranges.push_back(host_device(ws.res_shape.data(), bodies.shape.data(), n * sizeof(Shape)));
    ranges.push_back(host_device(ws.res_semi.data(), bodies.semi_axes.data(), n * sizeof(Vec3<double>)));
    ranges.push_back(host_device(ws.res_orient.data(), bodies.orientation.data(), n * sizeof(Quat<double>)));
  }
  upload_resident(b, ranges);
}

void resident_splice(CudaBackend& b, std::span<const std::size_t> leaving, std::span<const std::size_t> at,
                     const BodiesView& arrivals) {
  static_assert(sizeof(std::size_t) == sizeof(std::uint64_t));
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  Workspace& ws = b.m_ws;
  const std::size_t n = ws.res_count, l = leaving.size(), m = at.size(), out = n - l + m;
  struct Field {
    Bytes* rows;
    const void* host;  // the arrivals'
    std::size_t row_bytes;
  };
  std::vector<Field> fields{{&ws.res_pos, arrivals.position.data(), sizeof(Vec3<double>)},
                            {&ws.res_rad, arrivals.radius.data(), sizeof(double)}};
  if (ws.res_reported) fields.push_back({&ws.res_report, arrivals.report.data(), 1});
  if (ws.res_ided) fields.push_back({&ws.res_id, arrivals.id.data(), sizeof(std::int64_t)});
  if (ws.res_shaped) {
    fields.push_back({&ws.res_shape, arrivals.shape.data(), sizeof(Shape)});
    fields.push_back({&ws.res_semi, arrivals.semi_axes.data(), sizeof(Vec3<double>)});
    fields.push_back({&ws.res_orient, arrivals.orientation.data(), sizeof(Quat<double>)});
  }
  // temp: the leaving rows, the places, then the arrivals' rows of the field being spliced
  std::size_t arrival_bytes = 0;
  for (const Field& f : fields) arrival_bytes = std::max(arrival_bytes, cuda::align16(m * f.row_bytes));
  const std::size_t index_bytes =
      cuda::align16(l * sizeof(std::uint64_t)) + cuda::align16(m * sizeof(std::uint64_t));
  ws.reserve({{&ws.temp, index_bytes + arrival_bytes}}, "resident splice");
  auto* d_leaving = reinterpret_cast<std::uint64_t*>(ws.temp.data());
  auto* d_at = reinterpret_cast<std::uint64_t*>(ws.temp.data() + cuda::align16(l * sizeof(std::uint64_t)));
  std::byte* d_arrivals = ws.temp.data() + index_bytes;
  if (l > 0)
    CG_CUDA_CHECK(cudaMemcpyAsync(d_leaving, leaving.data(), l * sizeof(std::uint64_t),
                                  cudaMemcpyHostToDevice, b.m_stream));
  if (m > 0)
    CG_CUDA_CHECK(
        cudaMemcpyAsync(d_at, at.data(), m * sizeof(std::uint64_t), cudaMemcpyHostToDevice, b.m_stream));
  for (const Field& f : fields) {
    // the old rows and the arrivals into canon_field (a download's scratch), then back into the
    // field's storage (grown when the rows grow; its old contents are in canon_field by then)
    if (m > 0)
      CG_CUDA_CHECK(cudaMemcpyAsync(d_arrivals, f.host, m * f.row_bytes, cudaMemcpyHostToDevice, b.m_stream));
    ws.reserve({{&ws.canon_field, out * f.row_bytes}}, "resident splice");
    if (n + m > 0) {
      if (f.row_bytes % sizeof(std::uint64_t) == 0) {
        using W = unsigned long long;
        cuda::splice_kernel<W><<<cuda::blocks_for(n + m), cuda::kBlock, 0, b.m_stream>>>(
            reinterpret_cast<const W*>(f.rows->data()), n, reinterpret_cast<const W*>(d_arrivals), m,
            d_leaving, l, d_at, f.row_bytes / sizeof(W), reinterpret_cast<W*>(ws.canon_field.data()));
      } else {
        using W = unsigned char;
        cuda::splice_kernel<W><<<cuda::blocks_for(n + m), cuda::kBlock, 0, b.m_stream>>>(
            reinterpret_cast<const W*>(f.rows->data()), n, reinterpret_cast<const W*>(d_arrivals), m,
            d_leaving, l, d_at, f.row_bytes, reinterpret_cast<W*>(ws.canon_field.data()));
      }
      CG_CUDA_CHECK_LAUNCH("splice_kernel");
    }
    // (the arrivals' upload of the next field waits for this kernel: one stream)
    CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
    ws.reserve({{f.rows, out * f.row_bytes}}, "resident bodies");
    cuda::device_copy(f.rows->data(), ws.canon_field.data(), out * f.row_bytes, b.m_stream);
  }
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
  ws.res_count = out;
}

DeviceBodiesView resident_view(const CudaBackend& b) {
  DeviceBodiesView v;
  v.position = reinterpret_cast<const double*>(b.m_ws.res_pos.data());
  v.radius = reinterpret_cast<const double*>(b.m_ws.res_rad.data());
  v.report = b.m_ws.res_reported ? reinterpret_cast<const std::uint8_t*>(b.m_ws.res_report.data()) : nullptr;
  v.count = b.m_ws.res_count;
  if (b.m_ws.res_shaped) {  // else null: the sphere-only path
    v.shape = reinterpret_cast<const Shape*>(b.m_ws.res_shape.data());
    v.semi_axes = reinterpret_cast<const double*>(b.m_ws.res_semi.data());
    v.orientation = reinterpret_cast<const double*>(b.m_ws.res_orient.data());
  }
  if (b.m_ws.res_ided) v.id = reinterpret_cast<const std::int64_t*>(b.m_ws.res_id.data());
  return v;
}

void resident_mark(CudaBackend& b) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  mark_stage(b.m_ws, b.m_ws.res_mark, b.m_stream, reinterpret_cast<const double*>(b.m_ws.res_pos.data()),
             b.m_ws.res_count);
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

Bounds resident_extent(CudaBackend& b, std::span<const std::int64_t> ids, bool marked, double& displacement) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  const Workspace& ws = b.m_ws;
  return extent_stage(b.m_ws, b.m_h_counters, b.m_stream, reinterpret_cast<const double*>(ws.res_pos.data()),
                      reinterpret_cast<const double*>(ws.res_rad.data()),
                      marked ? reinterpret_cast<const double*>(ws.res_mark.data()) : nullptr, ws.res_count,
                      ids, displacement);
}

// Rows [first, first + count) of positions and radii between the resident DEVICE arrays and host
// memory (page-locked when the caller pinned it: Engine::pin_host).
void resident_copy(CudaBackend& b, std::size_t first, std::size_t count, Vec3<double>* position,
                   double* radius, bool to_device) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  auto* d_pos = reinterpret_cast<Vec3<double>*>(b.m_ws.res_pos.data()) + first;
  auto* d_rad = reinterpret_cast<double*>(b.m_ws.res_rad.data()) + first;
  if (to_device) {
    upload_resident(b, {host_device(d_pos, position, count * sizeof(Vec3<double>)),
                        host_device(d_rad, radius, count * sizeof(double))});
    return;
  }
  CG_CUDA_CHECK(
      cudaMemcpyAsync(position, d_pos, count * sizeof(Vec3<double>), cudaMemcpyDeviceToHost, b.m_stream));
  CG_CUDA_CHECK(cudaMemcpyAsync(radius, d_rad, count * sizeof(double), cudaMemcpyDeviceToHost, b.m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

// Rows [first, first + count) of the resident semi-axes and orientations (a null host pointer: that
// field is not copied), as resident_copy.
void resident_shape_copy(CudaBackend& b, std::size_t first, std::size_t count, Vec3<double>* semi_axes,
                         Quat<double>* orientation, bool to_device) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  std::vector<HostDevice> ranges;
  auto copy = [&](void* host, std::byte* device, std::size_t row_bytes) {
    if (!host) return;
    void* d = device + first * row_bytes;
    if (to_device)
      ranges.push_back(host_device(d, host, count * row_bytes));
    else
      CG_CUDA_CHECK(cudaMemcpyAsync(host, d, count * row_bytes, cudaMemcpyDeviceToHost, b.m_stream));
  };
  copy(semi_axes, b.m_ws.res_semi.data(), sizeof(Vec3<double>));
  copy(orientation, b.m_ws.res_orient.data(), sizeof(Quat<double>));
  if (to_device)
    upload_resident(b, ranges);
  else
    CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

namespace {
std::size_t packed_bytes(bool orientations) { return orientations ? 64 : 32; }
const double* doubles(const Bytes& b) { return reinterpret_cast<const double*>(b.data()); }
double* doubles(Bytes& b) { return reinterpret_cast<double*>(b.data()); }
const std::uint32_t* list_rows(const Workspace& ws, int list) {
  return reinterpret_cast<const std::uint32_t*>(ws.row_lists[list].data());
}
}  // namespace

void rows_set_list(CudaBackend& b, int list, std::span<const std::size_t> rows) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  const std::size_t m = rows.size();
  std::vector<std::uint32_t> u32(m);
  for (std::size_t k = 0; k < m; ++k) u32[k] = static_cast<std::uint32_t>(rows[k]);
  b.m_ws.reserve({{&b.m_ws.row_lists[list], m * sizeof(std::uint32_t)}}, "row lists");
  if (m > 0)
    CG_CUDA_CHECK(cudaMemcpyAsync(b.m_ws.row_lists[list].data(), u32.data(), m * sizeof(std::uint32_t),
                                  cudaMemcpyHostToDevice, b.m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

std::span<const std::byte> rows_gather(CudaBackend& b, int list, std::size_t count, bool orientations) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  Workspace& ws = b.m_ws;
  const std::size_t bytes = count * packed_bytes(orientations);
  b.m_h_gather.reserve(std::max<std::size_t>(bytes, 1));
  if (count == 0) return {b.m_h_gather.data(), 0};
  ws.reserve({{&ws.row_pack, bytes}}, "row gather");
  cuda::pack_rows_kernel<<<cuda::blocks_for(count), cuda::kBlock, 0, b.m_stream>>>(
      doubles(ws.res_pos), doubles(ws.res_rad), orientations ? doubles(ws.res_orient) : nullptr,
      list_rows(ws, list), count, doubles(ws.row_pack));
  CG_CUDA_CHECK_LAUNCH("pack_rows_kernel");
  CG_CUDA_CHECK(
      cudaMemcpyAsync(b.m_h_gather.data(), ws.row_pack.data(), bytes, cudaMemcpyDeviceToHost, b.m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
  return {b.m_h_gather.data(), bytes};
}

std::span<std::byte> rows_scatter_buffer(CudaBackend& b, std::size_t count, bool orientations) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  const std::size_t bytes = count * packed_bytes(orientations);
  b.m_h_scatter.reserve(std::max<std::size_t>(bytes, 1));
  return {b.m_h_scatter.data(), bytes};
}

void rows_scatter(CudaBackend& b, int list, std::size_t count, bool orientations) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  Workspace& ws = b.m_ws;
  const std::size_t bytes = count * packed_bytes(orientations);
  if (count == 0) return;
  ws.reserve({{&ws.row_pack, bytes}}, "row scatter");
  CG_CUDA_CHECK(
      cudaMemcpyAsync(ws.row_pack.data(), b.m_h_scatter.data(), bytes, cudaMemcpyHostToDevice, b.m_stream));
  cuda::unpack_rows_kernel<<<cuda::blocks_for(count), cuda::kBlock, 0, b.m_stream>>>(
      doubles(ws.row_pack), list_rows(ws, list), count, doubles(ws.res_pos), doubles(ws.res_rad),
      orientations ? doubles(ws.res_orient) : nullptr);
  CG_CUDA_CHECK_LAUNCH("unpack_rows_kernel");
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

void rows_copy(CudaBackend& to, CudaBackend& from, int from_list, int to_list, std::size_t count,
               bool orientations) {
  if (to.m_device != from.m_device)
    throw UsageError("copy_rows: the engines are on CUDA devices " + std::to_string(from.m_device) + " and " +
                     std::to_string(to.m_device));
  CG_CUDA_CHECK(cudaSetDevice(to.m_device));
  if (count == 0) return;
  Workspace& ws = to.m_ws;
  const Workspace& fs = from.m_ws;
  cuda::copy_rows_kernel<<<cuda::blocks_for(count), cuda::kBlock, 0, to.m_stream>>>(
      doubles(fs.res_pos), doubles(fs.res_rad), orientations ? doubles(fs.res_orient) : nullptr,
      list_rows(fs, from_list), list_rows(ws, to_list), count, doubles(ws.res_pos), doubles(ws.res_rad),
      orientations ? doubles(ws.res_orient) : nullptr);
  CG_CUDA_CHECK_LAUNCH("copy_rows_kernel");
  CG_CUDA_CHECK(cudaStreamSynchronize(to.m_stream));
}

std::vector<std::size_t> rows_outside(CudaBackend& b, int axis, double lo, double hi) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  Workspace& ws = b.m_ws;
  const std::size_t n = ws.res_count;
  if (n == 0) return {};
  if (n >= (std::size_t(1) << 31)) throw InputError("rows_outside: more than 2^31 - 1 resident rows");
  ws.reserve({{&ws.row_selected, 16 + n * sizeof(std::uint32_t)}}, "rows outside");
  auto* d_count = reinterpret_cast<std::uint32_t*>(ws.row_selected.data());
  auto* d_rows = reinterpret_cast<std::uint32_t*>(ws.row_selected.data() + 16);
  const cuda::OutsideInterval outside{doubles(ws.res_pos), axis, lo, hi};
  cub_run(ws, "rows outside", [&](void* t, std::size_t& bytes) {
    return cub::DeviceSelect::If(t, bytes, thrust::counting_iterator<std::uint32_t>(0), d_rows, d_count,
                                 int(n), outside, b.m_stream);
  });
  std::uint32_t count = 0;
  CG_CUDA_CHECK(cudaMemcpyAsync(&count, d_count, sizeof(count), cudaMemcpyDeviceToHost, b.m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
  std::vector<std::uint32_t> u32(count);
  if (count > 0)
    CG_CUDA_CHECK(cudaMemcpyAsync(u32.data(), d_rows, count * sizeof(std::uint32_t), cudaMemcpyDeviceToHost,
                                  b.m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
  return std::vector<std::size_t>(u32.begin(), u32.end());
}

}  // namespace cg::detail
