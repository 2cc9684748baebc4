#include "run/progress.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <cstdio>

namespace cg {

namespace {

// 1234 → "1.23 k", 3310000 → "3.31 M": three significant digits, SI prefixes.
std::string count_text(double n) {
  if (n < 1e3) return fmt::format("{:.0f}", n);
  if (n < 1e6) return fmt::format("{:.3g} k", n / 1e3);
  if (n < 1e9) return fmt::format("{:.3g} M", n / 1e6);
  return fmt::format("{:.3g} G", n / 1e9);
}

std::string duration_text(double s) {
  if (s < 60) return fmt::format("{:.0f} s", s);
  if (s < 3600) {
    const int minutes = static_cast<int>(s / 60);
    return fmt::format("{} min {:02d} s", minutes, static_cast<int>(s) - 60 * minutes);
  }
  return fmt::format("{:.1f} h", s / 3600);
}

}  // namespace

Progress::Progress(std::string what, std::string unit, std::uint64_t total, bool enabled)
    : m_what(std::move(what)),
      m_unit(std::move(unit)),
      m_total(total),
      m_drawing(enabled && isatty(fileno(stderr)) != 0),
      m_last(m_start) {}

Progress::~Progress() { finish(); }

std::string Progress::line(const std::string& what, const std::string& unit, std::uint64_t done,
                           std::uint64_t total, double seconds) {
  const double rate = seconds > 0 ? static_cast<double>(done) / seconds : 0;
  std::string text = fmt::format("{}: {}", what, count_text(static_cast<double>(done)));
  if (total > 0) {
    text += fmt::format(" / {} {} ({:.0f} %)", count_text(static_cast<double>(total)), unit,
                        100.0 * static_cast<double>(done) / static_cast<double>(total));
  } else {
    text += " " + unit;
  }
  if (rate > 0) text += fmt::format("  {}/s", count_text(rate));
  if (total > 0 && rate > 0 && done < total) {
    text += "  ETA " + duration_text(static_cast<double>(total - done) / rate);
  }
  return text;
}

void Progress::update(std::uint64_t done) {
  m_done = done;
  if (!m_drawing) return;
  const auto now = Clock::now();
  if (now - m_last < std::chrono::milliseconds(250)) return;
  m_last = now;
  const double seconds = std::chrono::duration<double>(now - m_start).count();
  std::fprintf(stderr, "\r\033[K%s", line(m_what, m_unit, m_done, m_total, seconds).c_str());
  std::fflush(stderr);
  m_drawn = true;
}

void Progress::finish() {
  if (m_drawn) {
    std::fprintf(stderr, "\r\033[K");
    std::fflush(stderr);
    m_drawn = false;
  }
}

}  // namespace cg
