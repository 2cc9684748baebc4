#pragma once
// HostVector: the host vector of the engine's inputs and outputs, for arrays of millions of elements.
// g++-safe public header (part of engine.hpp through contacts.hpp).
// HostAllocator: elements are default-initialised, so a resize does not sweep the memory with zeros
//   (the writer that follows — a parallel copy, a file read — is the first touch, in parallel where it
//   runs in parallel). Storage of 1 MiB or more comes from HostPool: 2 MiB-aligned, offered to
//   transparent huge pages (madvise, where the kernel has them) from 4 MiB, and kept for the process
//   when freed, so that the next array of about its size (the next call's contacts, the CPU stages'
//   scratch) takes it without a page fault: a fresh block costs its first touch, the kernel zeroing
//   every page, as much as the CPU backend's own writing of a million bodies' contacts.
#include <sys/mman.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <iterator>
#include <map>
#include <mutex>
#include <new>
#include <utility>
#include <vector>

namespace cg {
namespace detail {
// CONTACTGRID_HUGE_PAGES=0 turns the madvise hint off (measurement knob: the kernel's compaction for
// huge pages can cost more than the page faults it saves when several processes allocate at once).
inline bool huge_pages_wanted() {
  static const bool wanted = [] {
    const char* v = std::getenv("CONTACTGRID_HUGE_PAGES");
    return !(v && v[0] == '0');
  }();
  return wanted;
}

// The process's pool of large host blocks (HostAllocator, and the CPU stages' Array:
// host/scratch_pool.hpp). Blocks of at least k_pooled_min bytes are pooled: rounded up to 2 MiB,
// 2 MiB-aligned, offered to transparent huge pages from 4 MiB; a request takes the smallest free block
// of at least its size and at most twice it. The free blocks held stay below a cap:
// CONTACTGRID_HOST_POOL_MIB (default 1024; 0 frees every block at once, as without a pool); a block
// that would exceed it is freed, the largest held first. release_all() frees them all.
class HostPool {
 public:
  static constexpr std::size_t k_block = std::size_t(2) << 20;       // huge page
  static constexpr std::size_t k_pooled_min = std::size_t(1) << 20;  // smaller ones: operator new
  static constexpr std::size_t k_small_align = 64;

  // Never destroyed: arrays of static objects may be freed after the other statics' destructors.
  static HostPool& instance() {
    static HostPool* pool = new HostPool;
    return *pool;
  }

  // A block of at least `bytes` (a pooled one: rounded up to k_block).
  void* allocate(std::size_t bytes) {
    if (bytes < k_pooled_min) return ::operator new(bytes, std::align_val_t(k_small_align));
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
      ::operator delete(p, std::align_val_t(k_small_align));
      return;
    }
    std::lock_guard<std::mutex> lock(m_mutex);
    auto at = m_size.find(p);
    const std::size_t size = at != m_size.end() ? at->second : rounded(bytes);
    if (at != m_size.end()) m_size.erase(at);
    m_free.emplace(size, p);
    m_held += size;
    trim(m_cap);
  }

  // Lowers the cap on the free blocks held to at most `bytes` (a run under a memory limit: what the
  // pool keeps counts against the limit too) and frees what exceeds it.
  void cap_at_most(std::size_t bytes) noexcept {
    std::lock_guard<std::mutex> lock(m_mutex);
    m_cap = std::min(m_cap, bytes);
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

  // Page-locked blocks (the CUDA backend's downloads straight into the result vectors,
  // cuda/transfer.cuh): lock_block(p) page-locks the pooled block in use at p through `lock` on its
  // first call and keeps it locked while the pool holds it, free or in use; `unlock` runs before the
  // pool frees it. Returns the block's size, 0 when p is no pooled block in use or `lock` refuses.
  using LockFn = bool (*)(void*, std::size_t);
  using UnlockFn = void (*)(void*);
  std::size_t lock_block(void* p, LockFn lock, UnlockFn unlock) {
    std::lock_guard<std::mutex> guard(m_mutex);
    auto at = m_size.find(p);
    if (at == m_size.end()) return 0;
    if (m_locked.count(p)) return at->second;
    if (!lock(p, at->second)) return 0;
    m_locked.emplace(p, unlock);
    return at->second;
  }
  // Whether the block in use at p is page-locked (lock_block).
  bool block_locked(void* p) {
    std::lock_guard<std::mutex> guard(m_mutex);
    return m_locked.count(p) != 0;
  }

 private:
  HostPool() {
    const char* v = std::getenv("CONTACTGRID_HOST_POOL_MIB");
    m_cap = v ? std::size_t(std::strtoull(v, nullptr, 10)) << 20 : std::size_t(1024) << 20;
  }
  static std::size_t rounded(std::size_t bytes) { return (bytes + k_block - 1) / k_block * k_block; }
  // Frees the largest free blocks until at most `cap` bytes are held (the mutex is held).
  void trim(std::size_t cap) noexcept {
    while (m_held > cap && !m_free.empty()) {
      auto last = std::prev(m_free.end());
      m_held -= last->first;
      if (auto l = m_locked.find(last->second); l != m_locked.end()) {
        l->second(l->first);
        m_locked.erase(l);
      }
      ::operator delete(last->second, std::align_val_t(k_block));
      m_free.erase(last);
    }
  }

  std::mutex m_mutex;
  std::multimap<std::size_t, void*> m_free;  // size → block
  std::map<void*, std::size_t> m_size;       // blocks in use → their pooled size
  std::map<void*, UnlockFn> m_locked;        // page-locked blocks, free or in use → their unlock
  std::size_t m_held = 0, m_cap = 0;
};
}  // namespace detail

// The host pool keeps at most `bytes` of free blocks from now on (see detail::HostPool).
inline void cap_host_pool(std::size_t bytes) noexcept { detail::HostPool::instance().cap_at_most(bytes); }

template <class T>
struct HostAllocator {
  using value_type = T;
  HostAllocator() = default;
  template <class U>
  HostAllocator(const HostAllocator<U>&) noexcept {}

  T* allocate(std::size_t n) { return static_cast<T*>(detail::HostPool::instance().allocate(n * sizeof(T))); }
  void deallocate(T* p, std::size_t n) noexcept { detail::HostPool::instance().release(p, n * sizeof(T)); }
  // Default-initialisation when no value is given (trivial types: left as they are).
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    if constexpr (sizeof...(Args) == 0)
      ::new (static_cast<void*>(p)) U;
    else
      ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
  template <class U>
  bool operator==(const HostAllocator<U>&) const noexcept {
    return true;
  }
};

template <class T>
using HostVector = std::vector<T, HostAllocator<T>>;

}  // namespace cg
