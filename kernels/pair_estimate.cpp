// pair_estimate.cpp: the check of a broad phase's estimated pair tests (see pair_estimate.hpp).
#include "pair_estimate.hpp"

#include <algorithm>
#include <cstdio>

#include "errors.hpp"

namespace cg {

bool pair_work_unusual(const PairEstimate& e) {
  const double per_body = double(e.tests) / double(std::max<std::uint64_t>(e.bodies, 1));
  return e.tests >= 1'000'000'000ull && per_body >= 1000;
}

bool follows_progress(const PairEstimate& e, const PairLimits& limits) {
  return limits.on_progress != nullptr && *limits.on_progress && pair_work_unusual(e);
}

std::string describe_seconds(double seconds) {
  char text[40];
  if (seconds < 90)
    std::snprintf(text, sizeof text, "%.2g s", seconds);
  else if (seconds < 90 * 60)
    std::snprintf(text, sizeof text, "%.2g min", seconds / 60);
  else if (seconds < 48 * 3600)
    std::snprintf(text, sizeof text, "%.2g h", seconds / 3600);
  else
    std::snprintf(text, sizeof text, "%.2g days", seconds / 86400);
  return text;
}

std::string describe(const PairEstimate& e) {
  char text[200];
  std::snprintf(text, sizeof text,
                "about %.2g pair tests (%.3g per body; the fullest cell holds %llu entries", double(e.tests),
                double(e.tests) / double(std::max<std::uint64_t>(e.bodies, 1)),
                static_cast<unsigned long long>(e.largest));
  std::string out = text;
  if (e.tests_per_second > 0) {
    std::snprintf(text, sizeof text, " at %.2g tests a second)", e.tests_per_second);
    out += "; about " + describe_seconds(double(e.tests) / e.tests_per_second) + text;
  } else {
    out += ")";
  }
  return out;
}

void check_pair_estimate(const PairEstimate& e, const PairLimits& limits) {
  if (limits.on_estimate != nullptr && *limits.on_estimate) (*limits.on_estimate)(e);
  if (limits.max_tests > 0 && e.tests > limits.max_tests)
    throw LimitError("the pair stage would make " + describe(e) + ", more than --max-pair-tests " +
                     std::to_string(limits.max_tests) +
                     ": the bodies crowd into few cells (one body far larger than the rest sizes the cells, "
                     "or bodies are stacked); raise the limit to run it anyway");
}

}  // namespace cg
