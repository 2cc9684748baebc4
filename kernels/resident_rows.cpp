// A halo's rows on the host (see resident_rows.hpp).
#include "resident_rows.hpp"

#include <omp.h>

#include <cstring>

namespace cg::detail {

namespace {
constexpr std::size_t k_parallel_rows = std::size_t(1) << 14;

std::size_t row_bytes(bool orientations) { return orientations ? 64 : 32; }
}  // namespace

void pack_rows(const RowArrays& from, std::span<const std::size_t> list, bool orientations, std::byte* out,
               int threads) {
  const std::size_t m = list.size(), bytes = row_bytes(orientations);
#pragma omp parallel for num_threads(threads) schedule(static) if (m > k_parallel_rows)
  for (std::size_t k = 0; k < m; ++k) {
    const std::size_t i = list[k];
    std::byte* row = out + k * bytes;
    std::memcpy(row, &from.position[i], sizeof(Vec3<double>));
    std::memcpy(row + 24, &from.radius[i], sizeof(double));
    if (orientations) std::memcpy(row + 32, &from.orientation[i], sizeof(Quat<double>));
  }
}

void unpack_rows(const std::byte* in, std::span<const std::size_t> list, bool orientations,
                 const RowArrays& into, int threads) {
  const std::size_t m = list.size(), bytes = row_bytes(orientations);
#pragma omp parallel for num_threads(threads) schedule(static) if (m > k_parallel_rows)
  for (std::size_t k = 0; k < m; ++k) {
    const std::size_t i = list[k];
    const std::byte* row = in + k * bytes;
    std::memcpy(&into.position[i], row, sizeof(Vec3<double>));
    std::memcpy(&into.radius[i], row + 24, sizeof(double));
    if (orientations) std::memcpy(&into.orientation[i], row + 32, sizeof(Quat<double>));
  }
}

void copy_rows(const RowArrays& from, std::span<const std::size_t> from_list, const RowArrays& into,
               std::span<const std::size_t> to_list, bool orientations, int threads) {
  const std::size_t m = to_list.size();
#pragma omp parallel for num_threads(threads) schedule(static) if (m > k_parallel_rows)
  for (std::size_t k = 0; k < m; ++k) {
    const std::size_t i = from_list[k], j = to_list[k];
    into.position[j] = from.position[i];
    into.radius[j] = from.radius[i];
    if (orientations) into.orientation[j] = from.orientation[i];
  }
}

std::vector<std::size_t> rows_outside(const Vec3<double>* position, std::size_t n, int axis, double lo,
                                      double hi, int threads) {
  const int parts = n > k_parallel_rows ? threads : 1;
  std::vector<std::vector<std::size_t>> found(static_cast<std::size_t>(parts));
#pragma omp parallel for num_threads(parts) schedule(static, 1) if (parts > 1)
  for (int t = 0; t < parts; ++t) {
    const std::size_t begin = n * static_cast<std::size_t>(t) / static_cast<std::size_t>(parts);
    const std::size_t end = n * static_cast<std::size_t>(t + 1) / static_cast<std::size_t>(parts);
    std::vector<std::size_t>& mine = found[static_cast<std::size_t>(t)];
    for (std::size_t i = begin; i < end; ++i) {
      const double x = axis == 0 ? position[i].x : axis == 1 ? position[i].y : position[i].z;
      if (!(x > lo && x < hi)) mine.push_back(i);
    }
  }
  std::vector<std::size_t> rows;
  for (const std::vector<std::size_t>& f : found) rows.insert(rows.end(), f.begin(), f.end());
  return rows;
}

}  // namespace cg::detail
