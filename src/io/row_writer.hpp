#pragma once
// The raw rows of a contact file's datasets, copied into the file at their offsets by a team of
// threads, with no HDF5 call (contact_file.hpp: phase (b) and the streamed appends).
//
// Two ways, the same bytes in the file:
// - pwrite: each block of rows is one pwrite loop. On Linux every write to one file takes the file's
//   lock, so the threads' writes into new pages (page allocation, zeroing, copy) run one at a time.
// - map: the file's byte range is mapped shared; each thread faults its block's pages in itself
//   (MADV_POPULATE_WRITE, which reports a full filesystem as an error instead of a SIGBUS) and copies
//   its rows there, so the page allocations run on all threads at once. A block whose pages cannot be
//   populated is written by pwrite instead, which then names the real reason (ENOSPC, EFBIG).
// CONTACTGRID_IO_WRITE=map chooses the mapping; unset (or pwrite) the pwrite loop. Any other value is
// refused (UsageError). The mapping is opt-in: one thread populates and copies slower than one pwrite
// loop (dev VM, tmpfs, 375 MiB: 0.95 against 1.3–1.8 GB/s), so it pays only where many threads share the
// file (BENCHMARKS.md §29; jobs/gpu_io_check.sh measures both).
#include <cstdint>
#include <vector>

namespace cg {

struct ContactFileLayout;

// A run of whole rows of one dataset, written by one thread.
struct RowBlock {
  std::size_t dataset;               // index into the layout's datasets (for messages)
  const unsigned char* src;          // the rows in memory
  std::uint64_t offset, bytes, row;  // file offset, length, first row (for messages)
};

// Rows [from, from + count) of dataset k (at `src`), to the file from `offset` on, in blocks of at most
// 4 MiB; `row` is the file row of `from`.
void add_row_blocks(std::vector<RowBlock>& blocks, std::size_t k, const unsigned char* src,
                    std::uint64_t row_bytes, std::uint64_t from, std::uint64_t count, std::uint64_t offset,
                    std::uint64_t row);

enum class RowWriteMode { pwrite, map };
// The team size from which the mapped writer is the default: the kernel runs one pwrite into a file at
// a time, while each thread populates its own mapped pages; with 16 threads the mapping writes the
// 2^24 sphere job's 375 MB at 3.4 GB/s against pwrite's 2.3, with 2 it is the slower (BENCHMARKS §29).
inline constexpr int kMapWriteThreads = 8;
// The mode CONTACTGRID_IO_WRITE asks for (pwrite or map; unset: map for a team of at least
// kMapWriteThreads threads, else pwrite).
RowWriteMode row_write_mode(int team);

// The blocks, written into layout.temp by a team of `threads` (0: all). IoError naming the dataset and
// the rows of the first block that failed.
void write_row_blocks(const ContactFileLayout& layout, const std::vector<RowBlock>& blocks, int threads);

}  // namespace cg
