#pragma once
// The allocator of the backend's Thrust calls (the design card: Thrust where an algorithm does a
// stage's job at a hand-written kernel's speed), with thrust::cuda::par_nosync(alloc).on(stream):
// Thrust sizes its own temporary storage and asks here. Blocks are cached by size and never freed
// until the backend goes: every Thrust call runs on the backend's one stream, so a block handed back
// is free for the next call in stream order, and a caller that steps many times allocates nothing
// after the first steps (EngineStats::device_allocations counts the cudaMalloc calls here too).
#include <cstddef>
#include <map>

#include "cuda/device_buffer.cuh"

namespace cg::detail {

class ThrustAllocator {
 public:
  using value_type = char;
  ThrustAllocator() = default;
  ThrustAllocator(const ThrustAllocator&) = delete;
  ThrustAllocator& operator=(const ThrustAllocator&) = delete;
  ~ThrustAllocator() {
    for (auto& [bytes, p] : m_free) cudaFree(p);
    for (auto& [p, bytes] : m_used) cudaFree(p);
  }

  // The smallest cached block of at least n bytes, else a new one (cudaMalloc: CudaError when the
  // device is out of memory).
  char* allocate(std::ptrdiff_t n) {
    const std::size_t bytes = n > 0 ? static_cast<std::size_t>(n) : 1;
    auto it = m_free.lower_bound(bytes);
    char* p = nullptr;
    std::size_t size = bytes;
    if (it != m_free.end()) {
      size = it->first;
      p = it->second;
      m_free.erase(it);
    } else {
      CG_CUDA_CHECK(cudaMalloc(reinterpret_cast<void**>(&p), bytes));
      ++allocations;
      m_held += bytes;
    }
    m_used.emplace(p, size);
    return p;
  }
  void deallocate(char* p, std::size_t) {
    auto it = m_used.find(p);
    if (it == m_used.end()) return;
    m_free.emplace(it->second, p);
    m_used.erase(it);
  }

  std::size_t held_bytes() const { return m_held; }
  std::uint64_t allocations = 0;  // cudaMalloc calls since the counter was reset

 private:
  std::multimap<std::size_t, char*> m_free;  // by size
  std::map<char*, std::size_t> m_used;
  std::size_t m_held = 0;
};

}  // namespace cg::detail
