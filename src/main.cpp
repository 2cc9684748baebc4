// contactgrid: entry point. Exceptions become one message and a documented exit code
// (docs/ERRORS.md): 0 ok, 1 validation FAIL, 2 usage, 3 bad input, 4 CUDA, 5 MPI, 6 I/O, 7 out of
// memory, 8 internal, 9 over a limit the user set, 128 + N stopped by signal N (run/stop.hpp).
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <new>
#include <optional>
#include <string>

#include "cli/cli.hpp"
#include "errors.hpp"
#include "run/stop.hpp"
#include "session.hpp"

namespace {

int g_rank = 0;
std::string g_prefix;     // "[rank r/N] " under MPI, else empty
bool g_returned = false;  // main is returning: exit() is the normal end

// exit() called before main returns (a library giving up, a test fault): the process says so, with its
// rank, and its registered temporaries are removed. MPI is not finalised, so the launcher ends the job.
void on_early_exit() {
  if (g_returned) return;
  cg::run_cleanup_actions();
  std::fprintf(stderr, "contactgrid: %sexited before the run finished\n", g_prefix.c_str());
  std::fflush(stderr);
}

// An exception that escapes where it cannot be caught (an OpenMP region, a destructor) ends the
// process through std::terminate: it is still reported as main reports it, with its exit code, and
// the registered temporaries are removed (a failed allocation in a worker thread is "out of host
// memory", exit 7, not an abort).
[[noreturn]] void on_terminate() {
  int code = 8;
  const char* what = "an exception escaped (std::terminate)";
  if (const std::exception_ptr e = std::current_exception()) {
    try {
      std::rethrow_exception(e);
    } catch (const cg::Error& error) {
      code = error.exit_code();
      what = error.what();
    } catch (const std::bad_alloc&) {
      code = 7;
      what = "out of host memory";
    } catch (const std::exception& error) {
      what = error.what();
    } catch (...) {
    }
  }
  cg::run_cleanup_actions();
  std::fprintf(stderr, "contactgrid: %s%s%s\n", code == 8 ? "internal error: " : "error: ", g_prefix.c_str(),
               what);
  std::fflush(stderr);
  ::_exit(code);
}

}  // namespace

int main(int argc, char** argv) {
  std::set_terminate(on_terminate);
  std::atexit(on_early_exit);
  int code = 0;
  // Outlives the handlers below: MPI is finalised (a synchronisation of all ranks) only after rank 0
  // has printed the error. Were it finalised first, another rank could exit non-zero before rank 0
  // printed, and the launcher, ending the job at the first failed rank, would cut the message off.
  std::optional<cg::Session> session;
  try {
    // Under mpirun this initialises MPI (every rank runs the same command line); otherwise it is a
    // one-rank session and MPI is never touched.
    session.emplace(&argc, &argv);
    g_rank = session->rank();
    if (session->uses_mpi()) g_prefix = session->prefix();
    cg::install_stop_handlers(session->size(), g_prefix);
    code = cg::run_cli(argc, argv, *session);
  } catch (const cg::Stopped& e) {
    code = e.exit_code();  // said below
  } catch (const cg::Error& e) {
    // Errors of a distributed run are agreed on by every rank: rank 0 prints the one message.
    if (g_rank == 0) std::fprintf(stderr, "contactgrid: error: %s\n", e.what());
    code = e.exit_code();
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "contactgrid: error: out of host memory\n");
    code = 7;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "contactgrid: internal error: %s\n", e.what());
    code = 8;
  }
  // A signal asked the run to stop (one rank: the stop point threw Stopped, or the run had already
  // finished): every temporary is gone; the process ends as the signal ends it.
  if (const int signal = cg::stop_signal()) {
    std::fprintf(stderr, "contactgrid: stopped by %s\n", cg::signal_name(signal));
    std::fflush(stderr);
    session.reset();
    cg::end_by_signal(signal);
  }
  g_returned = true;
  return code;
}
