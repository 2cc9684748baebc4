// The host's file-write bandwidth, for the write stage of BENCHMARKS.md §21 (not a test): MIB of
// page-cache-resident data written into a new file in DIR as the contact writer does (blocks of 4 MiB,
// pwrite on THREADS OpenMP threads) and, for comparison, through a shared mapping of the file
// (posix_fallocate, then parallel memcpy: "mmap"; or the contact writer's mapped mode, src/io/row_writer:
// the file sized sparse, each thread populating its block's pages and copying them: "map"), best and
// median of REPETITIONS, the file's creation included.
//   file_write_bandwidth DIR [MIB=375] [THREADS=all] [REPETITIONS=5]
// Prints one line per mode: mode, threads, MB, best and median GB/s.
#include <fcntl.h>
#include <omp.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#ifndef MADV_POPULATE_WRITE
#define MADV_POPULATE_WRITE 23
#endif

namespace {

constexpr std::size_t kBlock = std::size_t(4) << 20;

// One write of `src` into a new file at `path`; false on any failure.
enum class Mode { pwrite, mmap, map };

bool write_file(const std::string& path, const std::vector<unsigned char>& src, Mode mode, int threads) {
  const std::size_t bytes = src.size(), blocks = (bytes + kBlock - 1) / kBlock;
  ::unlink(path.c_str());
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return false;
  bool ok = true;
  if (mode == Mode::pwrite) {
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1) reduction(&& : ok)
    for (std::size_t b = 0; b < blocks; ++b) {
      const std::size_t at = b * kBlock, len = std::min(kBlock, bytes - at);
      ok = ok && ::pwrite(fd, src.data() + at, len, static_cast<off_t>(at)) == static_cast<ssize_t>(len);
    }
  } else if (mode == Mode::mmap ? ::posix_fallocate(fd, 0, static_cast<off_t>(bytes)) != 0
                                : ::ftruncate(fd, static_cast<off_t>(bytes)) != 0) {
    ok = false;
  } else {
    void* m = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    if (m == MAP_FAILED) {
      ok = false;
    } else {
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1) reduction(&& : ok)
      for (std::size_t b = 0; b < blocks; ++b) {
        const std::size_t at = b * kBlock;
        if (mode == Mode::map)
          ok = ::madvise(static_cast<unsigned char*>(m) + at, std::min(kBlock, bytes - at),
                         MADV_POPULATE_WRITE) == 0 &&
               ok;
        std::memcpy(static_cast<unsigned char*>(m) + at, src.data() + at, std::min(kBlock, bytes - at));
      }
      ok = ::munmap(m, bytes) == 0;
    }
  }
  ok = ::close(fd) == 0 && ok;
  return ok;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: file_write_bandwidth DIR [MIB=375] [THREADS=all] [REPETITIONS=5]\n");
    return 2;
  }
  const std::string path = std::string(argv[1]) + "/file_write_bandwidth.tmp";
  const std::size_t mib = argc > 2 ? std::strtoull(argv[2], nullptr, 10) : 375;
  const int threads = argc > 3 && std::atoi(argv[3]) > 0 ? std::atoi(argv[3]) : omp_get_max_threads();
  const int repetitions = argc > 4 ? std::max(1, std::atoi(argv[4])) : 5;
  std::vector<unsigned char> src(mib << 20);
  for (std::size_t i = 0; i < src.size(); ++i) src[i] = static_cast<unsigned char>(i * 131);
  for (const Mode mode : {Mode::pwrite, Mode::mmap, Mode::map}) {
    std::vector<double> s;
    for (int r = 0; r < repetitions; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      if (!write_file(path, src, mode, threads)) {
        std::fprintf(stderr, "%s: write failed\n", path.c_str());
        ::unlink(path.c_str());
        return 1;
      }
      s.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    std::sort(s.begin(), s.end());
    const double mb = double(src.size()) / 1e6;
    std::printf("%s threads %d MB %.1f best_GBps %.2f median_GBps %.2f\n",
                mode == Mode::pwrite ? "pwrite"
                : mode == Mode::mmap ? "mmap"
                                     : "map",
                threads, mb, mb / 1e3 / s.front(), mb / 1e3 / s[s.size() / 2]);
  }
  ::unlink(path.c_str());
  return 0;
}
