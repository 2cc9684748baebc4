#pragma once
// How a run ends early: the signals that stop it, and the cleanup actions that then tidy up after it
// (docs/ERRORS.md "Stopped by a signal").
//
// SIGINT, SIGTERM, SIGPIPE and SIGXFSZ stop a run (install_stop_handlers, called by main):
//   one rank   the first signal asks the run to stop (stop_signal() != 0); the run stops at its next
//              stop point (stop_point(): between the stages of detect, before a file is renamed into
//              place, between the steps of a simulation) by throwing Stopped, which unwinds normally:
//              every temporary is removed by its owner, a simulation marks its run incomplete. When the
//              run has not ended CONTACTGRID_STOP_GRACE seconds later (default 5; 0: at once), or on
//              a second SIGINT or SIGTERM, it ends at once (below).
//   ranks > 1  the first signal ends the rank at once: ranks cannot agree to stop together without
//              communicating, and the launcher ends the others (SIGTERM), which end at once as well.
// Ending at once: every registered cleanup action runs inside the signal handler, then the process
// ends as the signal's default action ends it (SIGINT, SIGTERM, SIGPIPE: so a calling shell sees the
// signal and, e.g., leaves its loop), or with status 153 for SIGXFSZ (its default action would dump
// core). The exit status a shell reports is 128 + the signal's number either way: 130 SIGINT,
// 141 SIGPIPE, 143 SIGTERM, 153 SIGXFSZ. SIGPIPE and SIGXFSZ, which the kernel raises at a failing
// write, never count as the second signal.
//
// Cleanup actions are registered while what they tidy exists: every "<path>.tmp.<pid>" an output is
// written to (src/io registers them), a run directory to mark incomplete. Their storage is fixed
// (kCleanupSlots slots, paths and texts copied in), so the handler reads no memory the program may be
// freeing; each action runs once at most, and only unlink, open, write and close are called.
#include <cstddef>
#include <string>

namespace cg {

// The signal handlers above; `ranks`: the ranks of the run (> 1: the first signal ends at once);
// `prefix` starts the handlers' messages ("[rank r/N] " under MPI). Safe to call again (the last
// call's settings hold).
void install_stop_handlers(int ranks, const std::string& prefix = "");

// The signal that asked the run to stop; 0 when none did.
int stop_signal() noexcept;

// A stop point: throws Stopped when a signal asked the run to stop.
void stop_point();

// "SIGINT", "SIGTERM", … ("signal N" for others).
const char* signal_name(int signal) noexcept;

// Ends the process as `signal` does (see above) after a stop: no return.
[[noreturn]] void end_by_signal(int signal);

// ---- cleanup actions ------------------------------------------------------------------------------

constexpr std::size_t kCleanupSlots = 64;
constexpr std::size_t kCleanupPathBytes = 4096;  // PATH_MAX, with the terminating zero
constexpr std::size_t kCleanupTextBytes = 4096;

// One registered action; unregistered by release() or the destructor (move-only).
class CleanupAction {
 public:
  // unlink(path): a temporary the process writes.
  static CleanupAction remove_file(const std::string& path);
  // path created or truncated, then `text` written: a marker ("this run did not finish").
  static CleanupAction write_file(const std::string& path, const std::string& text);
  // `text` appended to path (created if missing): a last line for a log.
  static CleanupAction append_file(const std::string& path, const std::string& text);

  CleanupAction() = default;
  ~CleanupAction() { release(); }
  CleanupAction(CleanupAction&& other) noexcept : m_slot(other.m_slot) { other.m_slot = -1; }
  CleanupAction& operator=(CleanupAction&& other) noexcept;
  CleanupAction(const CleanupAction&) = delete;
  CleanupAction& operator=(const CleanupAction&) = delete;

  // Unregisters the action without running it (its file was renamed into place or removed).
  void release() noexcept;
  bool active() const noexcept { return m_slot >= 0; }

 private:
  explicit CleanupAction(int slot) : m_slot(slot) {}
  int m_slot = -1;
};

// The same for code whose temporary is not one object's (a contact file written in phases, by several
// processes): remove_on_stop registers unlink(path), forget_on_stop unregisters it (one registration).
void remove_on_stop(const std::string& path);
void forget_on_stop(const std::string& path) noexcept;

// Runs every registered action now and unregisters it (async-signal-safe; called by the handlers and
// before a rank aborts the job). Returns how many ran.
std::size_t run_cleanup_actions() noexcept;

// How many actions are registered (tests).
std::size_t cleanup_actions_registered() noexcept;

}  // namespace cg
