#pragma once
// The CPU backend's scratch memory: the stages' Array (host/stages.hpp) takes its storage from the
// process's pool of large host blocks (HostPool, host_vector.hpp), as HostVector does. A fresh array
// costs its first touch: the kernel zeroes every page (huge pages included) as a stage writes it, as
// much as the stage's own work at a million bodies. The arrays a call frees go back to the pool, and
// the next call's arrays of about the same size (the same scene, or one of similar size, with a new
// engine or the same) take them without a page fault. cg::detail::host::release_scratch_pool() frees
// every free block.
#include <cstddef>
#include <new>
#include <utility>
#include <vector>

#include "host_vector.hpp"

namespace cg::detail::host {

using ScratchPool = cg::detail::HostPool;

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
