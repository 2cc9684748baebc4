#pragma once
// A child process the test can signal while it runs: started with posix_spawn (no shell between, so
// a signal reaches the program itself), stdout and stderr into one pipe the test reads, extra
// environment variables added to the test's own.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

extern char** environ;

namespace cg::test {

class ChildProcess {
 public:
  using Clock = std::chrono::steady_clock;

  // argv[0] is the program's path. Throws std::runtime_error when it cannot start.
  ChildProcess(const std::vector<std::string>& argv, const std::vector<std::string>& extra_env) {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0) throw std::runtime_error("pipe2 failed");
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, fds[1], STDOUT_FILENO);
    posix_spawn_file_actions_adddup2(&actions, fds[1], STDERR_FILENO);
    std::vector<char*> args, env;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    for (char** e = environ; *e; ++e) env.push_back(*e);
    for (const auto& e : extra_env) env.push_back(const_cast<char*>(e.c_str()));
    env.push_back(nullptr);
    const int rc = ::posix_spawn(&m_pid, args[0], &actions, nullptr, args.data(), env.data());
    posix_spawn_file_actions_destroy(&actions);
    ::close(fds[1]);
    m_fd = fds[0];
    if (rc != 0) {
      ::close(m_fd);
      throw std::runtime_error("cannot start " + argv[0]);
    }
  }
  ~ChildProcess() {
    if (!m_status) {
      ::kill(m_pid, SIGKILL);
      ::waitpid(m_pid, nullptr, 0);
    }
    if (m_fd >= 0) ::close(m_fd);
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  pid_t pid() const { return m_pid; }
  const std::string& output() const { return m_output; }

  // Reads the output until it contains `needle` (true) or `seconds` have passed or the output ended.
  bool wait_for_output(const std::string& needle, double seconds) {
    const auto end =
        Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
    while (m_output.find(needle) == std::string::npos) {
      if (!read_some(end)) return m_output.find(needle) != std::string::npos;
    }
    return true;
  }

  void signal(int sig) const { ::kill(m_pid, sig); }

  // Still running (no wait)?
  bool running() {
    if (m_status) return false;
    int status = 0;
    if (::waitpid(m_pid, &status, WNOHANG) == m_pid) m_status = status;
    return !m_status;
  }

  // The wait status once the process ended (its output read to the end), or nothing after `seconds`.
  std::optional<int> wait(double seconds) {
    const auto end =
        Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
    while (read_some(end)) {
    }
    while (!m_status && Clock::now() < end) {
      int status = 0;
      if (::waitpid(m_pid, &status, WNOHANG) == m_pid) {
        m_status = status;
        break;
      }
      ::usleep(10000);
    }
    return m_status;
  }

 private:
  // One read of the pipe, waiting until `end`; false at the end of the output or the deadline.
  bool read_some(Clock::time_point end) {
    if (m_fd < 0) return false;
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - Clock::now()).count();
    if (left <= 0) return false;
    pollfd p{m_fd, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left)) <= 0) return false;
    char buf[4096];
    const ssize_t n = ::read(m_fd, buf, sizeof buf);
    if (n <= 0) {
      ::close(m_fd);
      m_fd = -1;
      return false;
    }
    m_output.append(buf, static_cast<std::size_t>(n));
    return true;
  }

  pid_t m_pid = -1;
  int m_fd = -1;
  std::string m_output;
  std::optional<int> m_status;
};

// "exit 3", "signal 2 (Interrupt)" …: a wait status in words, for failure messages.
inline std::string status_text(const std::optional<int>& status) {
  if (!status) return "still running";
  if (WIFEXITED(*status)) return "exit " + std::to_string(WEXITSTATUS(*status));
  if (WIFSIGNALED(*status))
    return "signal " + std::to_string(WTERMSIG(*status)) + " (" + strsignal(WTERMSIG(*status)) + ")";
  return "status " + std::to_string(*status);
}

}  // namespace cg::test
