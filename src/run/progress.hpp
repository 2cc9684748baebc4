#pragma once
// One updating line on the terminal for long work (generate, detect with steps, validate, bench, study,
// simulate): what is done of how much, the rate and the time left, e.g.
//   validate: 1.20 M / 3.31 M contacts (36 %)  410 k/s  ETA 5 s
// It writes to stderr only when stderr is a terminal and the run is not quiet, redraws at most a few
// times a second, and clears its line when it finishes, so that logs and pipes see nothing of it.
#include <chrono>
#include <cstdint>
#include <string>

namespace cg {

class Progress {
 public:
  // `what` names the work ("validate"), `unit` what is counted ("contacts"), `total` how many (0 when
  // unknown: then no percentage and no ETA). `enabled` false (-q) keeps it silent everywhere.
  Progress(std::string what, std::string unit, std::uint64_t total, bool enabled = true);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // Sets how much is done; redraws when a quarter second has passed since the last line.
  void update(std::uint64_t done);
  void add(std::uint64_t more) { update(m_done + more); }
  // Clears the line (called by the destructor too).
  void finish();

  // Whether this process draws at all: stderr is a terminal and not quiet.
  bool drawing() const { return m_drawing; }

  // The line as it is drawn, for tests: `seconds` since the start with `done` of the total.
  static std::string line(const std::string& what, const std::string& unit, std::uint64_t done,
                          std::uint64_t total, double seconds);

 private:
  using Clock = std::chrono::steady_clock;
  std::string m_what, m_unit;
  std::uint64_t m_total, m_done = 0;
  bool m_drawing;
  bool m_drawn = false;
  Clock::time_point m_start = Clock::now(), m_last;
};

}  // namespace cg
