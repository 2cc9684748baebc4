#pragma once
// Contact identity across steps (docs/FORMAT.md §2's history fields), shared by both backends: each contact
// row of a step carries `age` (steps the pair has touched without a break, 0 on its first: Bullet's
// lifeTime) and `previous_row` (the pair's row in the previous step's contacts, -1 when new).
//
// A pair is keyed by the GLOBAL ids of its bodies (a < b), so the identity does not depend on which
// rank found the pair or on the bodies' local rows. Both steps' rows are sorted by key (the engine's
// (id_a, id_b) order, mapped monotonically to global ids), so the row of a pair in the previous step
// is a binary search of its key in the previous keys: lower_bound_key here (host, the device's own
// kernel), lower_bound_key_near (the device's default: from the row's own place) or Thrust's
// vectorised lower_bound (cuda/history.cuh) — the same position every way, then
// history_of turns that position into the two fields. Integers only: the backends agree exactly.
#include <cstddef>
#include <cstdint>

#include "core/config.hpp"

namespace cg {

// (a, b) global ids of a pair, a < b, in the rows' lexicographic order.
struct PairKey {
  std::int64_t a = 0, b = 0;
};
CG_HD bool operator<(const PairKey& x, const PairKey& y) { return x.a < y.a || (x.a == y.a && x.b < y.b); }
CG_HD bool operator==(const PairKey& x, const PairKey& y) { return x.a == y.a && x.b == y.b; }

// The key of a contact row whose ids are `a`, `b`: the rows' ids themselves, or, when `global` is
// given, global[a], global[b] (the rows' ids are then local indices into it, ascending with it).
CG_HD PairKey pair_key(std::int64_t a, std::int64_t b, const std::int64_t* global) {
  return global ? PairKey{global[a], global[b]} : PairKey{a, b};
}

// The first position p in the sorted keys[0, m) with !(keys[p] < key) (m when none).
CG_HD std::size_t lower_bound_key(const PairKey* keys, std::size_t m, const PairKey& key) {
  std::size_t lo = 0, hi = m;
  while (lo < hi) {
    const std::size_t mid = lo + (hi - lo) / 2;
    if (keys[mid] < key)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

// The same position as lower_bound_key, searched from a guess: steps doubling away from `guess` until
// they bracket the position, then a binary search between them. A contact's row moves little from one
// step to the next, so guessed from the row's own index its previous position is a few reads away,
// next to the neighbouring rows' (coalesced on the device), where a search from the middle of all the
// keys reads about log2(m) places far apart.
CG_HD std::size_t lower_bound_key_near(const PairKey* keys, std::size_t m, const PairKey& key,
                                       std::size_t guess) {
  if (m == 0) return 0;
  if (guess >= m) guess = m - 1;
  std::size_t lo = 0, hi = m, step = 1;  // the position lies in [lo, hi]
  if (keys[guess] < key) {               // after guess: keys[lo - 1] < key
    lo = guess + 1;
    while (lo + step - 1 < m && keys[lo + step - 1] < key) {
      lo += step;
      step *= 2;
    }
    hi = lo + step - 1 < m ? lo + step - 1 : m;
  } else {  // at or before guess: !(keys[hi] < key)
    hi = guess;
    while (hi >= step && !(keys[hi - step] < key)) {
      hi -= step;
      step *= 2;
    }
    lo = hi >= step ? hi - step + 1 : 0;
  }
  return lo + lower_bound_key(keys + lo, hi - lo, key);
}

// A row's history fields.
struct RowHistory {
  std::int64_t age = 0, previous_row = -1;
};

// The history of a row with key `key` whose lower bound in the previous keys[0, m) is `p`, given the
// previous rows' ages: continued (age + 1, row p) when the previous step has the pair, else new.
CG_HD RowHistory history_of(const PairKey* keys, const std::int64_t* ages, std::size_t m, std::size_t p,
                            const PairKey& key) {
  if (p < m && keys[p] == key) return {ages[p] + 1, static_cast<std::int64_t>(p)};
  return {};
}

}  // namespace cg
