#pragma once
// An environment variable (a CONTACTGRID_ knob) set for the guard's life, its former value (or its
// absence) restored after: the tests of a path behind a knob run it beside the default in one process.
#include <cstdlib>
#include <optional>
#include <string>

namespace cg::test {

class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : m_name(name) {
    if (const char* was = std::getenv(name)) m_was = was;
    ::setenv(name, value, 1);
  }
  ~ScopedEnv() {
    if (m_was)
      ::setenv(m_name.c_str(), m_was->c_str(), 1);
    else
      ::unsetenv(m_name.c_str());
  }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;

 private:
  std::string m_name;
  std::optional<std::string> m_was;
};

}  // namespace cg::test
