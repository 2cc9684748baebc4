#pragma once
// Host vectors of millions of elements: reserve, and offer the untouched storage to transparent huge
// pages (madvise, where the kernel has them), so the resize or writes that follow take few page
// faults. Only the hint differs from std::vector::reserve; contents and capacity are the same.
#include <sys/mman.h>

#include <cstdint>
#include <vector>

namespace cg::detail {

template <class T>
void reserve_huge(std::vector<T>& v, std::size_t n) {
  v.reserve(n);
#if defined(MADV_HUGEPAGE)
  constexpr std::uintptr_t huge = std::uintptr_t(2) << 20;
  const auto lo = (reinterpret_cast<std::uintptr_t>(v.data() + v.size()) + huge - 1) & ~(huge - 1);
  const auto hi = reinterpret_cast<std::uintptr_t>(v.data() + v.capacity()) & ~(huge - 1);
  if (hi > lo) ::madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_HUGEPAGE);
#endif
}

}  // namespace cg::detail
