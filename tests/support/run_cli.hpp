#pragma once
// Runs the contactgrid executable (cli_binary(), support/paths.hpp) with a shell argument
// string, for the tests that drive the command line end to end.
#include <sys/wait.h>

#include <cstdio>
#include <string>

#include "support/paths.hpp"

namespace cg::test {

struct CliResult {
  int code;            // exit status; -1 when the process could not run or did not exit normally
  std::string output;  // stdout + stderr
};

inline CliResult run_cli(const std::string& args) {
  const std::string cmd = cli_binary() + " " + args + " 2>&1";
  CliResult r{-1, {}};
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  while (fgets(buf, sizeof buf, p)) r.output += buf;
  const int status = pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

}  // namespace cg::test
