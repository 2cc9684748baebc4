#pragma once
// HostVector: the host vector of the engine's inputs and outputs, for arrays of millions of elements.
// g++-safe public header (part of engine.hpp through contacts.hpp).
// HostAllocator: elements are default-initialised, so a resize does not sweep the memory with zeros
//   (the writer that follows — a parallel copy, a file read — is the first touch, in parallel where it
//   runs in parallel), and storage of 4 MiB or more is 2 MiB-aligned and offered to transparent huge
//   pages (madvise, where the kernel has them), so that first touch takes few page faults.
#include <sys/mman.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
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
}  // namespace detail

template <class T>
struct HostAllocator {
  using value_type = T;
  static constexpr std::size_t k_huge = std::size_t(2) << 20;

  HostAllocator() = default;
  template <class U>
  HostAllocator(const HostAllocator<U>&) noexcept {}

  static std::size_t alignment(std::size_t bytes) {
    return bytes >= 2 * k_huge ? k_huge : std::max(alignof(T), alignof(std::max_align_t));
  }
  T* allocate(std::size_t n) {
    const std::size_t bytes = n * sizeof(T);
    void* p = ::operator new(bytes, std::align_val_t(alignment(bytes)));
#if defined(MADV_HUGEPAGE)
    if (bytes >= 2 * k_huge && detail::huge_pages_wanted())
      ::madvise(p, bytes / k_huge * k_huge, MADV_HUGEPAGE);
#endif
    return static_cast<T*>(p);
  }
  void deallocate(T* p, std::size_t n) noexcept {
    ::operator delete(static_cast<void*>(p), std::align_val_t(alignment(n * sizeof(T))));
  }
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
