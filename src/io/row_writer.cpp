// row_writer.cpp: a contact file's raw rows into the file by pwrite or through a shared mapping, on a
// team of threads (see row_writer.hpp).
#include "io/row_writer.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <omp.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <optional>
#include <string_view>
#include <utility>

#include "errors.hpp"
#include "io/contact_file.hpp"

#ifndef MADV_POPULATE_WRITE
#define MADV_POPULATE_WRITE 23  // Linux 5.14; older kernels answer EINVAL and the rows go by pwrite
#endif

namespace cg {

namespace {

// One block by a pwrite loop: 0, or the errno of the failure.
int pwrite_block(int fd, const RowBlock& block) {
  std::uint64_t done = 0;
  while (done < block.bytes) {
    const ssize_t w =
        ::pwrite(fd, block.src + done, block.bytes - done, static_cast<off_t>(block.offset + done));
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return w < 0 ? errno : ENOSPC;  // no progress: treat as a full device
    done += static_cast<std::uint64_t>(w);
  }
  return 0;
}

// The file's bytes [from, from + bytes) mapped shared for writing (from: a multiple of the page size).
struct Mapping {
  unsigned char* base = nullptr;
  std::uint64_t from = 0, bytes = 0, page = 4096;
  // One block through the mapping: its pages populated by this thread, then its rows copied. False
  // when the pages cannot be populated (a full filesystem, no memory, an old kernel): nothing copied.
  bool copy(const RowBlock& block) const {
    const std::uint64_t at = block.offset - from, first_page = at / page * page;
    if (::madvise(base + first_page, at + block.bytes - first_page, MADV_POPULATE_WRITE) != 0) return false;
    std::memcpy(base + at, block.src, block.bytes);
    return true;
  }
};

// The mapping of the blocks' whole byte range, or nullopt when it cannot be had (the file is shorter
// than the rows' end, or mmap refuses): then every block goes by pwrite.
std::optional<Mapping> map_blocks(int fd, const std::vector<RowBlock>& blocks) {
  Mapping m;
  m.page = static_cast<std::uint64_t>(std::max(1L, ::sysconf(_SC_PAGESIZE)));
  std::uint64_t lo = blocks.front().offset, hi = 0;
  for (const RowBlock& b : blocks) {
    lo = std::min(lo, b.offset);
    hi = std::max(hi, b.offset + b.bytes);
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || static_cast<std::uint64_t>(st.st_size) < hi) return std::nullopt;
  m.from = lo / m.page * m.page;
  m.bytes = hi - m.from;
  void* p = ::mmap(nullptr, m.bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, static_cast<off_t>(m.from));
  if (p == MAP_FAILED) return std::nullopt;
  m.base = static_cast<unsigned char*>(p);
  return m;
}

}  // namespace

void add_row_blocks(std::vector<RowBlock>& blocks, std::size_t k, const unsigned char* src,
                    std::uint64_t row_bytes, std::uint64_t from, std::uint64_t count, std::uint64_t offset,
                    std::uint64_t row) {
  const std::uint64_t rows_per_block = std::max<std::uint64_t>(1, (std::uint64_t(4) << 20) / row_bytes);
  for (std::uint64_t r = 0; r < count; r += rows_per_block) {
    const std::uint64_t m = std::min(rows_per_block, count - r);
    blocks.push_back({k, src + (from + r) * row_bytes, offset + r * row_bytes, m * row_bytes, row + r});
  }
}

RowWriteMode row_write_mode(int team) {
  const char* knob = std::getenv("CONTACTGRID_IO_WRITE");
  const std::string_view v = knob ? knob : "";
  if (v.empty()) return team >= kMapWriteThreads ? RowWriteMode::map : RowWriteMode::pwrite;
  if (v == "pwrite") return RowWriteMode::pwrite;
  if (v == "map") return RowWriteMode::map;
  throw UsageError(fmt::format("CONTACTGRID_IO_WRITE={}: expected pwrite or map", v));
}

void write_row_blocks(const ContactFileLayout& layout, const std::vector<RowBlock>& blocks, int threads) {
  if (blocks.empty()) return;
  const int team = threads > 0 ? threads : omp_get_max_threads();
  const bool mapped = row_write_mode(team) == RowWriteMode::map;
  const int fd = ::open(layout.temp.c_str(), (mapped ? O_RDWR : O_WRONLY) | O_CLOEXEC);
  if (fd < 0) {
    const int e = errno;
    throw IoError(
        fmt::format("{}: cannot open {} for writing: {}", layout.path, layout.temp, std::strerror(e)));
  }
  const std::optional<Mapping> map = mapped ? map_blocks(fd, blocks) : std::nullopt;
  std::mutex failed_mutex;
  std::optional<std::pair<std::size_t, int>> failed;  // (block, errno) of the first failed block
  const std::ptrdiff_t nb = static_cast<std::ptrdiff_t>(blocks.size());
#pragma omp parallel for num_threads(team) schedule(dynamic, 1) if (nb > 1)
  for (std::ptrdiff_t b = 0; b < nb; ++b) {
    const RowBlock& block = blocks[static_cast<std::size_t>(b)];
    const int error = map && map->copy(block) ? 0 : pwrite_block(fd, block);
    if (error) {
      std::lock_guard<std::mutex> guard(failed_mutex);
      if (!failed || b < static_cast<std::ptrdiff_t>(failed->first))
        failed.emplace(static_cast<std::size_t>(b), error);
    }
  }
  const int unmapped = map ? ::munmap(map->base, map->bytes) : 0;
  const int unmap_error = errno;
  const int closed = ::close(fd);
  const int close_error = errno;
  if (failed) {
    const RowBlock& block = blocks[failed->first];
    const ContactFileLayout::Dataset& d = layout.datasets[block.dataset];
    throw IoError(fmt::format("{}: {}: cannot write rows {} to {} (into {}): {}", layout.path, d.name,
                              block.row, block.row + block.bytes / d.row_bytes - 1, layout.temp,
                              std::strerror(failed->second)));
  }
  if (unmapped != 0 || closed != 0) {
    throw IoError(fmt::format("{}: cannot close {} after writing rows: {}", layout.path, layout.temp,
                              std::strerror(unmapped != 0 ? unmap_error : close_error)));
  }
}

}  // namespace cg
