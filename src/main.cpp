// contactgrid: entry point. Exceptions become one message and a documented exit code:
// 0 ok, 1 validation FAIL, 2 usage, 3 bad input, 4 CUDA, 5 MPI, 6 I/O, 7 out of memory, 8 internal.
#include <cstdio>
#include <exception>
#include <new>
#include <optional>

#include "cli/cli.hpp"
#include "errors.hpp"
#include "session.hpp"

int main(int argc, char** argv) {
  int rank = 0;
  // Outlives the handlers below: MPI is finalised (a synchronisation of all ranks) only after rank 0
  // has printed the error. Were it finalised first, another rank could exit non-zero before rank 0
  // printed, and the launcher, ending the job at the first failed rank, would cut the message off.
  std::optional<cg::Session> session;
  try {
    // Under mpirun this initialises MPI (every rank runs the same command line); otherwise it is a
    // one-rank session and MPI is never touched.
    session.emplace(&argc, &argv);
    rank = session->rank();
    return cg::run_cli(argc, argv, *session);
  } catch (const cg::Error& e) {
    // Errors of a distributed run are agreed on by every rank: rank 0 prints the one message.
    if (rank == 0) std::fprintf(stderr, "contactgrid: error: %s\n", e.what());
    return e.exit_code();
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "contactgrid: error: out of host memory\n");
    return 7;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "contactgrid: internal error: %s\n", e.what());
    return 8;
  }
}
