#pragma once
// The room a skin build (EngineOptions::skin, core/skin.hpp) reserves for the kept candidate list that
// its pair stage writes in place (the CUDA cell-order build, cuda/pairs.cuh), before the walk has
// counted them (g++-safe, host only; a function of counts alone, tested on the CPU).
#include <algorithm>
#include <cstdint>

namespace cg {

// The previous build's count and a half (the bodies moved, the skin may have grown), or with no list
// kept yet one pair per (cell, body) entry; never less than the room already held. A walk that finds
// more writes them again by the counted path: the room changes the speed, never the list.
inline std::uint64_t kept_room(std::uint64_t previous, std::uint64_t entries, std::uint64_t held) {
  const std::uint64_t wanted = previous > 0 ? previous + previous / 2 : entries;
  return std::max(wanted, held);
}

// The count a build's room starts from: the kept list's, or where none is kept (the first build after
// calls without a skin) the last pair stage's count, which a skin's inflation only adds to.
inline std::uint64_t kept_room_basis(std::uint64_t kept, std::uint64_t last_pairs) {
  return kept > 0 ? kept : last_pairs;
}

}  // namespace cg
