#pragma once
// Runs the contactgrid binary of this build (CG_BINARY) with arguments through the shell and returns
// its exit code and its stdout + stderr together.
#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace cg::test {

struct Result {
  int code;
  std::string output;  // stdout + stderr
};

inline Result run(const std::string& args) {
  const std::string cmd = std::string(CG_BINARY) + " " + args + " 2>&1";
  Result r{-1, {}};
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  while (fgets(buf, sizeof buf, p)) r.output += buf;
  const int status = pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

}  // namespace cg::test
