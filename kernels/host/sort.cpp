// Host stage sort: stable radix sort of the (cell key, body) entries over plan.key_bits bits, or of each
// group of entries the entries stage wrote by the top digit, by its low bits.
#include "host/radix_sort.hpp"
#include "host/stages.hpp"

namespace cg::detail::host {

template <class Key>
void sort_entries(Entries<Key>& e, int key_bits, int threads) {
  if (e.digit_start.empty()) {
    radix_sort(e.keys, e.body, key_bits, threads);
    return;
  }
  // grouped by the top digit (fill_entries): each group by the bits below it
  const std::size_t n = e.size();
  Array<Key> key_tmp(n);
  Array<std::uint32_t> body_tmp(n);
  if (radix_sort_buckets(e.keys.data(), e.body.data(), key_tmp.data(), body_tmp.data(), e.digit_start.data(),
                         e.digit_start.size() - 1, e.digit_shift, threads)) {
    e.keys.swap(key_tmp);
    e.body.swap(body_tmp);
  }
  e.digit_start.clear();
}

template void sort_entries(Entries<std::uint32_t>&, int, int);
template void sort_entries(Entries<std::uint64_t>&, int, int);

}  // namespace cg::detail::host
