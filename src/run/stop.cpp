// stop.cpp: the stop signals and the cleanup actions (see stop.hpp).
#include "run/stop.hpp"

#include <fcntl.h>
#include <pthread.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>

#include "errors.hpp"

namespace cg {
namespace {

// A slot's life: free → filling (its registrant copies the action in) → active → free (released by
// its owner), or active → running (a handler, or run_cleanup_actions) → done → free (released by its
// owner). Only the owner frees a slot it registered, so a slot is never reused under an owner that
// still holds its index.
enum SlotState : int { kFree = 0, kFilling, kActive, kRunning, kDone };
enum class Kind : int { remove, write, append };

struct Slot {
  std::atomic<int> state{kFree};
  Kind kind = Kind::remove;
  std::size_t text_bytes = 0;
  char path[kCleanupPathBytes];
  char text[kCleanupTextBytes];
};

Slot g_slots[kCleanupSlots];
std::atomic<int> g_signal{0};  // the first stop signal
std::atomic<int> g_ranks{1};
std::atomic<unsigned> g_grace{5};
char g_prefix[64] = "";  // "[rank r/N] ", written before the handlers are installed

constexpr int kStopSignals[] = {SIGINT, SIGTERM, SIGPIPE, SIGXFSZ};

int claim(Kind kind, const std::string& path, const std::string& text) {
  if (path.empty() || path.size() >= kCleanupPathBytes)
    throw IoError(path.substr(0, 200) + ": a path of " + std::to_string(path.size()) + " bytes (at most " +
                  std::to_string(kCleanupPathBytes - 1) + ")");
  if (text.size() > kCleanupTextBytes)
    throw Error(path + ": a cleanup text of " + std::to_string(text.size()) + " bytes: internal error");
  for (std::size_t i = 0; i < kCleanupSlots; ++i) {
    Slot& s = g_slots[i];
    int expected = kFree;
    if (!s.state.compare_exchange_strong(expected, kFilling, std::memory_order_acquire)) continue;
    s.kind = kind;
    std::memcpy(s.path, path.c_str(), path.size() + 1);
    std::memcpy(s.text, text.data(), text.size());
    s.text_bytes = text.size();
    s.state.store(kActive, std::memory_order_release);
    return static_cast<int>(i);
  }
  throw Error("more than " + std::to_string(kCleanupSlots) + " cleanup actions registered: internal error");
}

void free_slot(int index) noexcept {
  Slot& s = g_slots[index];
  int expected = kActive;
  if (s.state.compare_exchange_strong(expected, kFree, std::memory_order_acq_rel)) return;
  if (expected == kDone) s.state.store(kFree, std::memory_order_release);
  // kRunning: a handler runs it now and the process is ending; the slot is left to it.
}

void write_all(int fd, const char* data, std::size_t bytes) noexcept {
  while (bytes > 0) {
    const ssize_t w = ::write(fd, data, bytes);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return;
    data += w;
    bytes -= static_cast<std::size_t>(w);
  }
}

void run_slot(const Slot& s) noexcept {
  if (s.kind == Kind::remove) {
    ::unlink(s.path);
    return;
  }
  const int flags = O_WRONLY | O_CREAT | O_CLOEXEC | (s.kind == Kind::append ? O_APPEND : O_TRUNC);
  const int fd = ::open(s.path, flags, 0644);
  if (fd < 0) return;
  write_all(fd, s.text, s.text_bytes);
  ::close(fd);
}

void say(const char* a, const char* b = "", const char* c = "", const char* d = "") noexcept {
  for (const char* part : {"contactgrid: ", static_cast<const char*>(g_prefix), a, b, c, d, "\n"})
    write_all(STDERR_FILENO, part, std::strlen(part));
}

// Ends the process as `signal` does, without a core dump (async-signal-safe).
[[noreturn]] void die(int signal) noexcept {
  if (signal == SIGXFSZ) ::_exit(128 + signal);
  struct sigaction dfl {};
  dfl.sa_handler = SIG_DFL;
  sigemptyset(&dfl.sa_mask);
  ::sigaction(signal, &dfl, nullptr);
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, signal);
  ::pthread_sigmask(SIG_UNBLOCK, &set, nullptr);
  ::raise(signal);
  ::_exit(128 + signal);
}

[[noreturn]] void end_now(int signal) noexcept {
  const bool removed = run_cleanup_actions() > 0;
  say("stopped by ", signal_name(signal), removed ? " (temporary files removed)" : "");
  die(signal);
}

void on_signal(int signal) {
  const int saved_errno = errno;
  int first = 0;
  const bool is_first = g_signal.compare_exchange_strong(first, signal);
  const bool user = signal == SIGINT || signal == SIGTERM;
  if (g_ranks.load() > 1 || g_grace.load() == 0) end_now(signal);
  if (!is_first) {
    if (user) end_now(signal);  // the second SIGINT or SIGTERM
    errno = saved_errno;        // a failing write's SIGPIPE or SIGXFSZ again
    return;
  }
  if (user)
    say(signal_name(signal), ": stopping at the next stop point (a second ", signal_name(signal),
        " stops at once)");
  ::alarm(g_grace.load());
  errno = saved_errno;
}

void on_alarm(int) { end_now(g_signal.load()); }

unsigned grace_seconds() {
  const char* text = std::getenv("CONTACTGRID_STOP_GRACE");
  if (text == nullptr || *text == '\0') return 5;
  char* end = nullptr;
  errno = 0;
  const unsigned long v = std::strtoul(text, &end, 10);
  if (*end != '\0' || errno != 0 || text[0] == '-' || v > 86400)
    throw UsageError(std::string("CONTACTGRID_STOP_GRACE=") + text +
                     ": not a whole number of seconds in [0, 86400]");
  return static_cast<unsigned>(v);
}

}  // namespace

const char* signal_name(int signal) noexcept {
  switch (signal) {
    case SIGINT:
      return "SIGINT";
    case SIGTERM:
      return "SIGTERM";
    case SIGPIPE:
      return "SIGPIPE";
    case SIGXFSZ:
      return "SIGXFSZ";
    case SIGALRM:
      return "SIGALRM";
    default:
      return "a signal";
  }
}

void install_stop_handlers(int ranks, const std::string& prefix) {
  g_grace.store(grace_seconds());
  const std::size_t n = std::min(prefix.size(), sizeof g_prefix - 1);
  std::memcpy(g_prefix, prefix.data(), n);
  g_prefix[n] = '\0';
  g_ranks.store(ranks);
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sa.sa_flags = SA_RESTART;  // blocking calls go on; the run looks at stop points
  sigemptyset(&sa.sa_mask);
  for (int s : kStopSignals) sigaddset(&sa.sa_mask, s);
  sigaddset(&sa.sa_mask, SIGALRM);
  for (int s : kStopSignals) ::sigaction(s, &sa, nullptr);
  struct sigaction alarm_sa = sa;
  alarm_sa.sa_handler = on_alarm;
  ::sigaction(SIGALRM, &alarm_sa, nullptr);
}

int stop_signal() noexcept { return g_signal.load(); }

void stop_point() {
  if (const int s = g_signal.load()) throw Stopped(s, std::string("stopped by ") + signal_name(s));
}

[[noreturn]] void end_by_signal(int signal) {
  ::alarm(0);
  run_cleanup_actions();
  die(signal);
}

// ---- cleanup actions ------------------------------------------------------------------------------

CleanupAction CleanupAction::remove_file(const std::string& path) {
  return CleanupAction(claim(Kind::remove, path, {}));
}
CleanupAction CleanupAction::write_file(const std::string& path, const std::string& text) {
  return CleanupAction(claim(Kind::write, path, text));
}
CleanupAction CleanupAction::append_file(const std::string& path, const std::string& text) {
  return CleanupAction(claim(Kind::append, path, text));
}

CleanupAction& CleanupAction::operator=(CleanupAction&& other) noexcept {
  if (this != &other) {
    release();
    m_slot = other.m_slot;
    other.m_slot = -1;
  }
  return *this;
}

void CleanupAction::release() noexcept {
  if (m_slot < 0) return;
  free_slot(m_slot);
  m_slot = -1;
}

void remove_on_stop(const std::string& path) { claim(Kind::remove, path, {}); }

void forget_on_stop(const std::string& path) noexcept {
  for (std::size_t i = 0; i < kCleanupSlots; ++i) {
    Slot& s = g_slots[i];
    const int state = s.state.load(std::memory_order_acquire);
    if ((state != kActive && state != kDone) || s.kind != Kind::remove) continue;
    if (std::strncmp(s.path, path.c_str(), kCleanupPathBytes) != 0) continue;
    free_slot(static_cast<int>(i));
    return;
  }
}

std::size_t run_cleanup_actions() noexcept {
  std::size_t ran = 0;
  for (Slot& s : g_slots) {
    int expected = kActive;
    if (!s.state.compare_exchange_strong(expected, kRunning, std::memory_order_acq_rel)) continue;
    run_slot(s);
    s.state.store(kDone, std::memory_order_release);
    ++ran;
  }
  return ran;
}

std::size_t cleanup_actions_registered() noexcept {
  std::size_t n = 0;
  for (const Slot& s : g_slots) n += s.state.load(std::memory_order_acquire) == kActive;
  return n;
}

}  // namespace cg
