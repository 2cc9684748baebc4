#pragma once
// The CPU backend's scratch memory (ScratchAllocator: the stages' Array, host/stages.hpp), kept in one
// pool for the process between calls. A fresh array costs its first touch: the kernel zeroes every page
// (huge pages included) as a stage writes it, as much as the stage's own work at a million bodies. The
// arrays a call frees go back to the pool, and the next call's arrays of about the same size (the same
// scene, or one of similar size, with a new engine or the same) take them without a page fault.
//
// Blocks of at least k_pooled_min bytes are pooled: rounded up to 2 MiB, 2 MiB-aligned and offered to
// transparent huge pages (as HostVector's); a request takes the smallest free block of at least its
// size and at most twice it. The free blocks held stay below a cap: CONTACTGRID_HOST_POOL_MIB
// (default 1024; 0 frees every block at once, as without a pool); a block that would exceed it is
// freed, the largest held first. cg::detail::host::release_scratch_pool() frees them all.
#include <sys/mman.h>

#include <cstddef>
#include <cstdlib>
#include <map>
#include <mutex>
#include <new>
#include <utility>
#include <vector>

#include "host_vector.hpp"

namespace cg::detail::host {

class ScratchPool {
 public:
  static constexpr std::size_t k_block = std::size_t(2) << 20;       // huge page
  static constexpr std::size_t k_pooled_min = std::size_t(1) << 20;  // smaller ones: operator new

  // Never destroyed: arrays of static objects may be freed after the other statics' destructors.
  static ScratchPool& instance() {
    static ScratchPool* pool = new ScratchPool;
    return *pool;
  }

  // A block of at least `bytes` (a pooled one: rounded up to k_block).
  void* allocate(std::size_t bytes) {
    if (bytes < k_pooled_min) return ::operator new(bytes, std::align_val_t(64));
    const std::size_t size = rounded(bytes);
    {
      std::lock_guard<std::mutex> lock(m_mutex);
      auto it = m_free.lower_bound(size);
      if (it != m_free.end() && it->first <= 2 * size) {
        void* p = it->second;
        m_held -= it->first;
        m_size[p] = it->first;
        m_free.erase(it);
        return p;
      }
    }
    void* p = ::operator new(size, std::align_val_t(k_block));
#if defined(MADV_HUGEPAGE)
    if (size >= 2 * k_block && huge_pages_wanted()) ::madvise(p, size, MADV_HUGEPAGE);
#endif
    std::lock_guard<std::mutex> lock(m_mutex);
    m_size[p] = size;
    return p;
  }

  void release(void* p, std::size_t bytes) noexcept {
    if (bytes < k_pooled_min) {
      ::operator delete(p, std::align_val_t(64));
      return;
    }
    std::unique_lock<std::mutex> lock(m_mutex);
    auto at = m_size.find(p);
    const std::size_t size = at != m_size.end() ? at->second : rounded(bytes);
    if (at != m_size.end()) m_size.erase(at);
    m_free.emplace(size, p);
    m_held += size;
    trim(m_cap);
  }

  // Frees every free block (blocks in use stay theirs).
  void release_all() noexcept {
    std::lock_guard<std::mutex> lock(m_mutex);
    trim(0);
  }

  std::size_t held_bytes() {
    std::lock_guard<std::mutex> lock(m_mutex);
    return m_held;
  }

 private:
  ScratchPool() {
    const char* v = std::getenv("CONTACTGRID_HOST_POOL_MIB");
    m_cap = v ? std::size_t(std::strtoull(v, nullptr, 10)) << 20 : std::size_t(1024) << 20;
  }
  static std::size_t rounded(std::size_t bytes) { return (bytes + k_block - 1) / k_block * k_block; }
  static bool huge_pages_wanted() { return cg::detail::huge_pages_wanted(); }
  // Frees the largest free blocks until at most `cap` bytes are held (the mutex is held).
  void trim(std::size_t cap) noexcept {
    while (m_held > cap && !m_free.empty()) {
      auto last = std::prev(m_free.end());
      m_held -= last->first;
      ::operator delete(last->second, std::align_val_t(k_block));
      m_free.erase(last);
    }
  }

  std::mutex m_mutex;
  std::multimap<std::size_t, void*> m_free;  // size → block
  std::map<void*, std::size_t> m_size;       // blocks in use → their pooled size
  std::size_t m_held = 0, m_cap = 0;
};

inline void release_scratch_pool() { ScratchPool::instance().release_all(); }

// The allocator of the stages' arrays: elements default-initialised (no zero sweep: every stage
// writes each element it sizes), storage from the pool.
template <class T>
struct ScratchAllocator {
  using value_type = T;
  ScratchAllocator() = default;
  template <class U>
  ScratchAllocator(const ScratchAllocator<U>&) noexcept {}
  T* allocate(std::size_t n) { return static_cast<T*>(ScratchPool::instance().allocate(n * sizeof(T))); }
  void deallocate(T* p, std::size_t n) noexcept { ScratchPool::instance().release(p, n * sizeof(T)); }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    if constexpr (sizeof...(Args) == 0)
      ::new (static_cast<void*>(p)) U;
    else
      ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
  template <class U>
  bool operator==(const ScratchAllocator<U>&) const noexcept {
    return true;
  }
};

// The stages' arrays (host/stages.hpp).
template <class T>
using Array = std::vector<T, ScratchAllocator<T>>;

}  // namespace cg::detail::host
