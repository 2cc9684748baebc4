#pragma once
// CUDA error checking, owning device/pinned buffers and the non-owning span views passed to kernels.
// Included by .cu files only (needs cuda_runtime.h).
#include <cuda_runtime.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <string>
#include <utility>

#include "errors.hpp"

namespace cg::cuda {

// Throws cg::CudaError "file:line: call: <cudaGetErrorString>" when `e` is not cudaSuccess.
[[noreturn]] void throw_cuda_error(cudaError_t e, const char* call, const char* file, int line);

#define CG_CUDA_CHECK(call)                                                                       \
  do {                                                                                            \
    const cudaError_t cg_err_ = (call);                                                           \
    if (cg_err_ != cudaSuccess) ::cg::cuda::throw_cuda_error(cg_err_, #call, __FILE__, __LINE__); \
  } while (0)

// After every kernel launch (`kernel`: its name, a string literal): launch-configuration errors surface
// here as "file:line: launch of <kernel>: <error>", asynchronous faults at the next synchronising call
// (which is checked too).
#define CG_CUDA_CHECK_LAUNCH(kernel)                                                  \
  do {                                                                                \
    const cudaError_t cg_err_ = cudaGetLastError();                                   \
    if (cg_err_ != cudaSuccess)                                                       \
      ::cg::cuda::throw_cuda_error(cg_err_, "launch of " kernel, __FILE__, __LINE__); \
  } while (0)

// Trivially copyable view of `size` elements in DEVICE memory; passed by value to kernels.
template <class T>
struct DeviceSpan {
  T* d_data = nullptr;
  std::size_t size = 0;
  __host__ __device__ T& operator[](std::size_t i) const { return d_data[i]; }
  __host__ __device__ T* data() const { return d_data; }
};

// Owning, move-only DEVICE allocation (cudaMalloc). reserve() grows geometrically and never shrinks;
// it DISCARDS the contents when it reallocates (callers reserve before a stage writes the buffer).
// Freed with cudaFree in the destructor (errors there are ignored: destructors do not throw).
template <class T>
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  ~DeviceBuffer() { release(); }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  DeviceBuffer(DeviceBuffer&& o) noexcept
      : m_data(std::exchange(o.m_data, nullptr)), m_capacity(std::exchange(o.m_capacity, 0)) {}
  DeviceBuffer& operator=(DeviceBuffer&& o) noexcept {
    if (this != &o) {
      release();
      m_data = std::exchange(o.m_data, nullptr);
      m_capacity = std::exchange(o.m_capacity, 0);
    }
    return *this;
  }

  // Capacity this buffer would have after reserve(count, geometric): 0 growth when it fits.
  std::size_t capacity_for(std::size_t count, bool geometric) const {
    if (count <= m_capacity) return m_capacity;
    if (!geometric || m_capacity == 0) return count;
    const std::size_t g = m_capacity + m_capacity / 2;
    return g > count ? g : count;
  }
  // Ensures capacity >= count; returns true when it (re)allocated.
  bool reserve(std::size_t count, bool geometric) {
    if (count <= m_capacity) return false;
    const std::size_t cap = capacity_for(count, geometric);
    release();
    void* p = nullptr;
    CG_CUDA_CHECK(cudaMalloc(&p, cap * sizeof(T)));
    m_data = static_cast<T*>(p);
    m_capacity = cap;
    return true;
  }
  std::size_t capacity() const { return m_capacity; }
  std::size_t bytes() const { return m_capacity * sizeof(T); }
  T* data() const { return m_data; }
  DeviceSpan<T> span(std::size_t count) const { return {m_data, count}; }
  // The same storage seen as `U` (the workspace reuses dead buffers; cudaMalloc aligns to 256 B).
  template <class U>
  DeviceSpan<U> span_as(std::size_t count) const {
    return {reinterpret_cast<U*>(m_data), count};
  }

 private:
  void release() {
    if (m_data) cudaFree(m_data);
    m_data = nullptr;
    m_capacity = 0;
  }
  T* m_data = nullptr;
  std::size_t m_capacity = 0;
};

// Owning, move-only pinned HOST allocation (cudaMallocHost) for staging transfers; grows like
// DeviceBuffer and never shrinks.
class PinnedBuffer {
 public:
  PinnedBuffer() = default;
  ~PinnedBuffer() {
    if (m_data) cudaFreeHost(m_data);
  }
  PinnedBuffer(const PinnedBuffer&) = delete;
  PinnedBuffer& operator=(const PinnedBuffer&) = delete;
  void reserve(std::size_t bytes) {
    if (bytes <= m_bytes) return;
    const std::size_t cap = bytes > m_bytes + m_bytes / 2 ? bytes : m_bytes + m_bytes / 2;
    if (m_data) cudaFreeHost(m_data);
    m_data = nullptr;
    m_bytes = 0;
    CG_CUDA_CHECK(cudaMallocHost(&m_data, cap));
    m_bytes = cap;
  }
  std::byte* data() const { return static_cast<std::byte*>(m_data); }
  std::size_t bytes() const { return m_bytes; }

 private:
  void* m_data = nullptr;
  std::size_t m_bytes = 0;
};

// A ring of pinned HOST slots for streamed transfers (transfer.cuh): the host fills or drains one slot
// while the copy engine moves another, and each slot's event says when its last copy is done. One ring
// per device for the whole process (pinned_ring), allocated at the first streamed transfer and reused
// by every later one, whatever engine makes it: pinning memory per call, or per engine (Python's
// detect() makes one a call), costs more than the pinned copy saves. A transfer holds `mutex()` while
// it fills or drains slots; the events keep a slot from being refilled while a copy still reads it.
class PinnedRing {
 public:
  static constexpr std::size_t kSlots = 8;

  PinnedRing() = default;
  ~PinnedRing() {
    for (cudaEvent_t e : m_done)
      if (e) cudaEventDestroy(e);
  }
  PinnedRing(const PinnedRing&) = delete;
  PinnedRing& operator=(const PinnedRing&) = delete;

  // Slots of `slot_bytes` (Tuning::transfer_slot_bytes), their events created. Waits for every slot's
  // last copy first: a transfer may start while the previous one's copies still run.
  void ready(std::size_t slot_bytes) {
    for (cudaEvent_t& e : m_done) {
      if (!e) CG_CUDA_CHECK(cudaEventCreateWithFlags(&e, cudaEventDisableTiming));
      if (slot_bytes != m_slot_bytes) CG_CUDA_CHECK(cudaEventSynchronize(e));
    }
    m_slots.reserve(kSlots * slot_bytes);
    m_slot_bytes = slot_bytes;
  }
  std::size_t slot_bytes() const { return m_slot_bytes; }
  std::mutex& mutex() { return m_mutex; }
  // Slot k of a transfer (k counts on; slots are reused in turn) and the event of its last copy.
  std::byte* slot(std::size_t k) const { return m_slots.data() + (k % kSlots) * m_slot_bytes; }
  cudaEvent_t done(std::size_t k) const { return m_done[k % kSlots]; }
  // Waits until slot k's previous copy is done (an event never recorded is done).
  void wait(std::size_t k) const { CG_CUDA_CHECK(cudaEventSynchronize(done(k))); }

 private:
  std::mutex m_mutex;
  PinnedBuffer m_slots;
  std::size_t m_slot_bytes = 0;
  std::array<cudaEvent_t, kSlots> m_done{};
};

// The process's ring for `device` (the current device when the call is made; kept until exit).
PinnedRing& pinned_ring(int device);

}  // namespace cg::cuda
