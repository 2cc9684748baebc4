// The contact contract of docs/FORMAT.md §2 checked on a contact set as given (validate.cpp's first
// step): ids inside the scene and never a body with itself, id_a < id_b, rows sorted by (id_a, id_b)
// and unique, every value finite; the datasets of equal length.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "errors.hpp"
#include "validate/validate_detail.hpp"

namespace cg::validate_detail {

bool check_contract(const Contacts<double>& c, std::int64_t bodies, ValidateReport& rep) {
  std::int64_t first_order = -1, first_unsorted = -1, first_dup = -1, first_bad = -1, first_nf = -1;
  for (std::size_t r = 0; r < c.size(); ++r) {
    const auto a = c.id_a[r], b = c.id_b[r];
    if (a < 0 || b < 0 || a >= bodies || b >= bodies || a == b) {
      if (rep.bad_ids++ == 0) first_bad = std::int64_t(r);
      continue;
    }
    if (a > b && rep.bad_id_order++ == 0) first_order = std::int64_t(r);
    if (r > 0) {  // on canonical keys, so one swapped row is one id-order failure, nothing else
      const auto pa = c.id_a[r - 1], pb = c.id_b[r - 1];
      const Key prev{std::min(pa, pb), std::max(pa, pb)}, cur{std::min(a, b), std::max(a, b)};
      if (cur < prev && rep.unsorted++ == 0) first_unsorted = std::int64_t(r);
      if (cur == prev && rep.duplicates++ == 0) first_dup = std::int64_t(r);
    }
    if ((!finite(c.position_on_a[r]) || !finite(c.position_on_b[r]) || !finite(c.normal_on_b[r]) ||
         !std::isfinite(c.distance[r])) &&
        rep.non_finite++ == 0)
      first_nf = std::int64_t(r);
  }
  auto row_ids = [&](std::int64_t r) {
    return fmt::format("row {}, ids ({}, {})", r, c.id_a[std::size_t(r)], c.id_b[std::size_t(r)]);
  };
  if (rep.bad_ids)
    rep.failures.push_back(fmt::format(
        "{} rows name ids outside 0 … {} or the same body twice (first: {}); they are not compared",
        rep.bad_ids, bodies - 1, row_ids(first_bad)));
  if (rep.bad_id_order)
    rep.failures.push_back(fmt::format(
        "id order: {} rows have id_a > id_b (first: {}); docs/FORMAT.md §2 requires id_a < id_b, A being the "
        "body with the smaller id",
        rep.bad_id_order, row_ids(first_order)));
  if (rep.unsorted)
    rep.failures.push_back(fmt::format(
        "not sorted: {} rows come before their predecessor (first: {}); docs/FORMAT.md §2 requires rows "
        "sorted by (id_a, id_b)",
        rep.unsorted, row_ids(first_unsorted)));
  if (rep.duplicates)
    rep.failures.push_back(fmt::format(
        "duplicates: {} rows repeat the pair of the row before (first: {}); each pair must appear once",
        rep.duplicates, row_ids(first_dup)));
  if (rep.non_finite)
    rep.failures.push_back(
        fmt::format("{} rows hold non-finite values (first: {})", rep.non_finite, row_ids(first_nf)));
  return rep.bad_ids == 0 && rep.bad_id_order == 0 && rep.unsorted == 0 && rep.duplicates == 0;
}

void check_lengths(const Contacts<double>& c) {
  const std::size_t k = c.id_a.size();
  if (c.id_b.size() != k || c.position_on_a.size() != k || c.position_on_b.size() != k ||
      c.normal_on_b.size() != k || c.distance.size() != k)
    throw InputError("validate: the contact datasets have different lengths");
}

}  // namespace cg::validate_detail
