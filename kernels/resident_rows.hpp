#pragma once
// A halo's rows on the host (Engine::gather_rows, scatter_rows, copy_rows, rows_outside): the CPU
// backend's, over its resident arrays. The CUDA backend does the same on the device
// (cuda/resident_rows.cuh), with the same packed layout: a row is its position (3 doubles) and radius
// (32 bytes), then with orientations its orientation (w, x, y, z; 64 bytes in all).
#include <cstddef>
#include <span>
#include <vector>

#include "core/quat.hpp"
#include "core/vec3.hpp"

namespace cg::detail {

// Resident arrays of the rows (orientation null: a scene without shape rows).
struct RowArrays {
  Vec3<double>* position = nullptr;
  double* radius = nullptr;
  Quat<double>* orientation = nullptr;
};

// Row k of `out` := row list[k] of `from`.
void pack_rows(const RowArrays& from, std::span<const std::size_t> list, bool orientations, std::byte* out,
               int threads);
// Row list[k] of `into` := row k of `in`.
void unpack_rows(const std::byte* in, std::span<const std::size_t> list, bool orientations,
                 const RowArrays& into, int threads);
// Row to_list[k] of `into` := row from_list[k] of `from` (the lists of one length).
void copy_rows(const RowArrays& from, std::span<const std::size_t> from_list, const RowArrays& into,
               std::span<const std::size_t> to_list, bool orientations, int threads);
// The rows i < n whose position[i] along `axis` is not in the open interval (lo, hi) (or not a
// number), ascending.
std::vector<std::size_t> rows_outside(const Vec3<double>* position, std::size_t n, int axis, double lo,
                                      double hi, int threads);

}  // namespace cg::detail
