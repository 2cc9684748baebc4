// Host stage order: radix sort of the candidate pairs by (a, b) (keys a << id_bits | b).
#include "host/radix_sort.hpp"
#include "host/stages.hpp"

namespace cg::detail::host {

void order_candidates(CandidatePairs& c, int threads) { radix_sort_keys(c.ab, 2 * c.id_bits, threads); }

}  // namespace cg::detail::host
