#pragma once
// A shell command line run by /bin/sh (or `shell`) for the tests that need the shell's own tools around the
// contactgrid binary (ulimit, a tmpfs in a private mount namespace): its output and exit status as
// the shell reports it (128 + N for a process ended by signal N).
#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace cg::test {

struct ShellResult {
  int code;            // the shell's exit status; -1 when it could not run
  std::string output;  // stdout + stderr
};

inline ShellResult run_shell(const std::string& script, const std::string& shell = "/bin/sh") {
  std::string quoted = "'";
  for (char c : script) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  quoted += "'";
  ShellResult r{-1, {}};
  FILE* p = popen((shell + " -c " + quoted + " 2>&1").c_str(), "r");
  if (!p) return r;
  char buf[4096];
  while (fgets(buf, sizeof buf, p)) r.output += buf;
  const int status = pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// Runs `script` in a private mount namespace with a tmpfs of `kib` KiB mounted on `dir` (an existing,
// empty directory): the filesystem fills up at that size, and vanishes with the namespace. After the
// script, the shell prints "LEFT:<names>" (what is left on the tmpfs) and exits with the script's
// status. code -1 and an empty output when no user namespace or tmpfs is available here.
inline ShellResult run_on_small_tmpfs(const std::string& dir, int kib, const std::string& script) {
  const std::string mount = "mount -t tmpfs -o size=" + std::to_string(kib) + "k tmpfs " + dir;
  if (run_shell("unshare -rm sh -c '" + mount + "' >/dev/null 2>&1").code != 0) return {-1, {}};
  return run_shell("unshare -rm sh -c '" + mount + " && { " + script + "; }; rc=$?; echo LEFT:$(ls -A " +
                   dir + "); exit $rc'");
}

}  // namespace cg::test
