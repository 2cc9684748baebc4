#pragma once
// Wall-clock seconds and the median of repeated timings, shared by every timed stage, the benches and
// the study. Host code, g++-safe.
#include <algorithm>
#include <chrono>
#include <vector>

namespace cg {

using WallClock = std::chrono::steady_clock;

// Seconds from `t` to now.
inline double seconds_since(WallClock::time_point t) {
  return std::chrono::duration<double>(WallClock::now() - t).count();
}

// The median of `v` (the mean of the two middle values for an even count; 0 when empty).
inline double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

}  // namespace cg
