// Host stage sort: stable radix sort of the (cell key, body) entries over plan.key_bits bits.
#include "host/radix_sort.hpp"
#include "host/stages.hpp"

namespace cg::detail::host {

template <class Key>
void sort_entries(Entries<Key>& e, int key_bits, int threads) {
  radix_sort(e.keys, e.body, key_bits, threads);
}

template void sort_entries(Entries<std::uint32_t>&, int, int);
template void sort_entries(Entries<std::uint64_t>&, int, int);

}  // namespace cg::detail::host
