// bullet_collide(): picks the Bullet flavour. Double Bullet is linked into this library and runs in
// process; float Bullet runs in the separate executable contactgrid-bullet-float (the two flavours
// export the same symbols and cannot share a process), through two files in a private temporary
// directory that is always removed.
//
// Invariants: the child gets an argv (no shell); a child that fails, crashes or writes a malformed
// file is an IoError quoting its exit status; the result says which btScalar produced it and it is
// checked against the flavour asked for; the child's peak resident memory comes back in its output.
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "errors.hpp"
#include "validate/bullet_oracle.hpp"

extern char** environ;

namespace cg {
namespace {

namespace fs = std::filesystem;

bool is_executable(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec) && ::access(p.c_str(), X_OK) == 0;
}

// A private directory (mode 0700) under $TMPDIR or /tmp, removed with everything in it.
class TempDir {
 public:
  TempDir() {
    const char* base = std::getenv("TMPDIR");
    std::string templ = std::string(base && *base ? base : "/tmp") + "/contactgrid-bullet-XXXXXX";
    std::vector<char> buf(templ.begin(), templ.end());
    buf.push_back('\0');
    if (!::mkdtemp(buf.data()))
      throw IoError("cannot create a temporary directory " + templ + ": " + std::strerror(errno));
    m_path = buf.data();
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(m_path, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const fs::path& path() const { return m_path; }

 private:
  fs::path m_path;
};

OracleResult run_float_executable(const OracleBodies& bodies, bool warm_step) {
  const std::string exe = bullet_float_executable();
  TempDir dir;
  const std::string in = (dir.path() / "bodies.bin").string();
  const std::string out = (dir.path() / "contacts.bin").string();
  write_oracle_input(in, bodies, warm_step);

  std::vector<std::string> args{exe, in, out};
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  if (int rc = ::posix_spawn(&pid, exe.c_str(), nullptr, nullptr, argv.data(), environ); rc != 0)
    throw IoError("cannot start " + exe + ": " + std::strerror(rc));
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) throw IoError("waiting for " + exe + ": " + std::strerror(errno));
  }
  if (WIFSIGNALED(status)) throw IoError(exe + " was killed by signal " + std::to_string(WTERMSIG(status)));
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    throw IoError(exe + " failed with exit status " + std::to_string(WEXITSTATUS(status)) +
                  " (its message is above)");
  return read_oracle_output(out);
}

}  // namespace

std::string bullet_float_executable() {
  const char* name = "contactgrid-bullet-float";
  std::vector<std::string> tried;
  if (const char* env = std::getenv("CONTACTGRID_BULLET_FLOAT"); env && *env) {
    if (is_executable(env)) return env;
    throw IoError(std::string("CONTACTGRID_BULLET_FLOAT=") + env + " is not an executable file");
  }
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path next_to_self = self.parent_path() / name;
    if (is_executable(next_to_self)) return next_to_self.string();
    tried.push_back(next_to_self.string());
  }
#ifdef CG_BULLET_FLOAT_BUILD_PATH
  if (is_executable(CG_BULLET_FLOAT_BUILD_PATH)) return CG_BULLET_FLOAT_BUILD_PATH;
  tried.push_back(CG_BULLET_FLOAT_BUILD_PATH);
#endif
  std::string msg = std::string("float Bullet oracle ") + name + " not found (looked at";
  for (const auto& t : tried) msg += " " + t;
  throw IoError(msg + "); set CONTACTGRID_BULLET_FLOAT to its path");
}

OracleResult bullet_collide(const OracleBodies& bodies, Precision bullet, bool warm_step) {
  const int want = bullet == Precision::fp64 ? 8 : 4;
  OracleResult r = bullet == Precision::fp64 ? bullet_native::collide(bodies, warm_step)
                                             : run_float_executable(bodies, warm_step);
  if (r.scalar_bytes != want)
    throw Error("Bullet oracle: asked for " + std::to_string(want * 8) + "-bit Bullet, got " +
                std::to_string(r.scalar_bytes * 8) + "-bit (build mixes the flavours)");
  return r;
}

}  // namespace cg
