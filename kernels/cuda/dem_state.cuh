#pragma once
// The CUDA backend of the granular dynamics (kernels/dem.hpp): its DEVICE state, shared by its stages
// (dem_integrate.cuh, dem_forces.cuh, dem_sums.cuh, dem_energy.cuh), sequenced by dem_backend.cu.
// Every kernel runs on the legacy default stream: the engine's own (blocking) stream is ordered
// after it, and the engine returns with its contacts complete, so the stages and the engine's
// detection follow each other with no extra synchronisation.
#include <algorithm>
#include <cstdint>
#include <iterator>

#include "core/dem_step.hpp"
#include "cuda/device_buffer.cuh"
#include "cuda/thrust_alloc.cuh"
#include "dem.hpp"
#include "dem_backend.hpp"

namespace cg::detail {

template <class T>
using DemBuffer = cuda::DeviceBuffer<T>;

// The step's stage timer (DemOptions::stage_times): an event on the legacy stream at the step's start
// and at the end of each DemStage; a stage's time is the span from the previous event to its own (on
// the device's timeline, so the host's gaps between launches count where they fall).
class DemStageEvents {
 public:
  DemStageEvents() = default;
  DemStageEvents(const DemStageEvents&) = delete;
  DemStageEvents& operator=(const DemStageEvents&) = delete;
  ~DemStageEvents() {
    for (cudaEvent_t& e : m_events)
      if (e) cudaEventDestroy(e);
  }
  bool on() const { return m_on; }
  void enable() {
    for (cudaEvent_t& e : m_events)
      if (!e) CG_CUDA_CHECK(cudaEventCreate(&e));
    m_on = true;
  }
  void start() {
    if (!m_on) return;
    std::fill(std::begin(m_marked), std::end(m_marked), false);
    CG_CUDA_CHECK(cudaEventRecord(m_events[0], cudaStreamLegacy));
  }
  void mark(DemStage s) {
    if (!m_on) return;
    const int i = static_cast<int>(s);
    CG_CUDA_CHECK(cudaEventRecord(m_events[i + 1], cudaStreamLegacy));
    m_marked[i] = true;
  }
  // Waits for the step's events and adds each marked stage's seconds to seconds[stage].
  void collect(double* seconds) {
    if (!m_on) return;
    int last = -1;
    for (int i = 0; i < kDemStages; ++i)
      if (m_marked[i]) last = i;
    if (last < 0) return;
    CG_CUDA_CHECK(cudaEventSynchronize(m_events[last + 1]));
    cudaEvent_t prev = m_events[0];
    for (int i = 0; i < kDemStages; ++i) {
      if (!m_marked[i]) continue;
      float ms = 0;
      CG_CUDA_CHECK(cudaEventElapsedTime(&ms, prev, m_events[i + 1]));
      seconds[i] += ms * 1e-3;
      prev = m_events[i + 1];
    }
  }

 private:
  cudaEvent_t m_events[kDemStages + 1] = {};
  bool m_marked[kDemStages] = {};
  bool m_on = false;
};

// The overlapped step's stream and events (dem_overlap.cuh): the halo's records move on a
// non-blocking stream of their own, ordered against the legacy stream by events (edge: the edge's
// passes done; sent: the records downloaded; received: scattered); interior_begin/end time the
// interior's passes, and sent their part after the download (stage times).
class DemHaloStream {
 public:
  DemHaloStream() = default;
  DemHaloStream(const DemHaloStream&) = delete;
  DemHaloStream& operator=(const DemHaloStream&) = delete;
  ~DemHaloStream() {
    for (cudaEvent_t e : {edge, sent, received, interior_begin, interior_end})
      if (e) cudaEventDestroy(e);
    if (stream) cudaStreamDestroy(stream);
  }
  void create() {
    if (stream) return;
    // the highest priority: the gather's and scatter's few blocks go before the interior's pending ones
    int least = 0, greatest = 0;
    CG_CUDA_CHECK(cudaDeviceGetStreamPriorityRange(&least, &greatest));
    CG_CUDA_CHECK(cudaStreamCreateWithPriority(&stream, cudaStreamNonBlocking, greatest));
    for (cudaEvent_t* e : {&edge, &received})
      CG_CUDA_CHECK(cudaEventCreateWithFlags(e, cudaEventDisableTiming));
    for (cudaEvent_t* e : {&sent, &interior_begin, &interior_end}) CG_CUDA_CHECK(cudaEventCreate(e));
  }
  cudaStream_t stream = nullptr;
  cudaEvent_t edge = nullptr, sent = nullptr, received = nullptr, interior_begin = nullptr,
              interior_end = nullptr;
};

class CudaDem {
 public:
  int device = 0;
  std::size_t count = 0;
  bool shapes = false;  // shape rows (ellipsoids present)
  // bodies
  DemBuffer<Vec3<double>> position, velocity, omega, momentum, force, torque, semi_axes;
  DemBuffer<Quat<double>> orientation;
  DemBuffer<dem::BodyProps> props;
  DemBuffer<Shape> shape;
  DemBuffer<double> radius;
  // contacts: terms of the step, springs and normals of this step and the last (current: the last);
  // a_sums (tuning: CONTACTGRID_DEM_TERMS, dem_forces.cuh): each body's sums over its rows as A
  // (a_force, a_torque) from the contact stage, no torque_a
  DemBuffer<Vec3<double>> contact_force, torque_a, torque_b, xi[2], normal[2], a_force, a_torque;
  bool a_sums = true;
  // store_all (tuning: CONTACTGRID_DEM_STORE=all): every term in double every step; else
  // (dem_forces.cuh) torques_from_points: the step's torques are not stored (the body stage takes
  // them from the rows' points, core/dem_step.hpp), and in fp32 the normals are kept as detected
  // (normal_f: this step's and the last, as normal)
  bool store_all = false, torques_from_points = false;
  DemBuffer<Vec3<float>> normal_f[2];
  DemBuffer<double> contact_energy;
  int current = 0;
  // the rows by B, the begins of each body's rows (sort: the radix sort's keys; counts: each row's
  // rank among its B's rows), walls, their springs and energies
  DemBuffer<std::uint32_t> b_keys[2], by_b[2], a_begin, b_begin, b_rank;
  DemBuffer<std::byte> sort_temp;
  bool sums_by_sort = false;  // tuning: CONTACTGRID_DEM_SUMS=sort
  bool segments_cub = false;  // tuning: CONTACTGRID_DEM_SEGMENTS=cub
  int min_blocks = 2;         // tuning: CONTACTGRID_DEM_BLOCKS (the force kernels' __launch_bounds__)
  DemStageEvents events;
  DemBuffer<dem::Wall> walls;
  int wall_count = 0;
  DemBuffer<Vec3<double>> wall_xi;
  DemBuffer<double> wall_energy, partials;
  ThrustAllocator thrust;
  // one rank's rows of a run over several ranks (dem_rows.cuh): the rows' global ids (null: none
  // set), the rows exchanged and their records, the positions at the mark; normals_f: the last
  // contact stage kept its normals in normal_f (else in normal)
  DemBuffer<std::int64_t> ids;
  bool has_ids = false;
  DemBuffer<std::uint32_t> row_index;
  DemBuffer<DemRow> row_records;
  DemBuffer<DemLogRow> log_rows;  // a log row's terms of chosen rows (dem_rows.cuh)
  // the halo (dem_rows.cuh: set_halo): its rows, their records on the device and in page-locked
  // host buffers reused every step
  DemBuffer<std::uint32_t> halo_send, halo_receive;
  std::size_t halo_sends = 0, halo_receives = 0;
  DemBuffer<DemRow> halo_records;
  cuda::PinnedBuffer halo_out, halo_in;
  bool halo_spheres = false;  // the records are DemSphereRow (else DemRow)
  // the overlapped step (dem_overlap.cuh): each row's edge flag (a halo row, sent or received), the
  // edge rows (ascending, once each), the halo's stream; interior_timed: the last overlapped step
  // recorded the interior's events
  DemBuffer<std::uint8_t> edge;
  DemBuffer<std::uint32_t> edge_rows;
  std::size_t edge_count = 0;
  DemHaloStream halo_stream;
  bool interior_timed = false;
  DemBuffer<Vec3<double>> mark;
  bool normals_f = false;

  dem::BodyArrays arrays() const {
    return {position.data(),  velocity.data(),    omega.data(),
            momentum.data(),  orientation.data(), force.data(),
            torque.data(),    props.data(),       shapes ? shape.data() : nullptr,
            semi_axes.data(), radius.data(),      count};
  }
};

}  // namespace cg::detail
