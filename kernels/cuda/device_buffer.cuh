#pragma once
// CUDA error checking, owning device/pinned buffers and the non-owning span views passed to kernels.
// Included by .cu files only (needs cuda_runtime.h).
#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>
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

}  // namespace cg::cuda
