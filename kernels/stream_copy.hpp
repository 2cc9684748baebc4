#pragma once
// A host copy whose stores bypass the caches (non-temporal), for large arrays that no one reads soon
// after: an ordinary store first reads its destination line into the cache (a third stream of memory
// traffic beside the source read and the write-back), a streaming store does not. The migration's
// merge of a rank's rows (splice_rows.hpp: gigabytes a rebuild, both ranks of a host at once) is
// bounded by the host's memory rate, so it moves two thirds of the bytes. Not for data the copy engine
// reads next (the pinned ring's slots stay in the last-level cache with plain stores: BENCHMARKS §35).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string_view>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace cg {

// Arrays at least this large are copied with streaming stores (CONTACTGRID_SPLICE_COPY=memcpy: never;
// the former copies): far above a core's share of the last-level cache.
inline bool stream_copy_wanted(std::size_t array_bytes) {
  static const bool off = [] {
    const char* v = std::getenv("CONTACTGRID_SPLICE_COPY");
    return v != nullptr && std::string_view(v) == "memcpy";
  }();
  return !off && array_bytes >= (std::size_t(32) << 20);
}

// memcpy's result: the head up to the destination's 16-byte boundary and the tail copied plainly, the
// 16-byte blocks between by streaming stores, then a fence (the stores are ordered before any later
// store of this thread, so a thread that joins this one sees them).
inline void stream_copy(void* dst, const void* src, std::size_t bytes) {
#if defined(__SSE2__)
  auto* d = static_cast<std::byte*>(dst);
  const auto* s = static_cast<const std::byte*>(src);
  const std::size_t head = std::min(bytes, (16 - reinterpret_cast<std::uintptr_t>(d) % 16) % 16);
  std::memcpy(d, s, head);
  d += head;
  s += head;
  bytes -= head;
  const std::size_t blocks = bytes / 16;
  for (std::size_t k = 0; k < blocks; ++k)
    _mm_stream_si128(reinterpret_cast<__m128i*>(d + 16 * k),
                     _mm_loadu_si128(reinterpret_cast<const __m128i*>(s + 16 * k)));
  std::memcpy(d + 16 * blocks, s + 16 * blocks, bytes - 16 * blocks);
  _mm_sfence();
#else
  std::memcpy(dst, src, bytes);
#endif
}

}  // namespace cg
