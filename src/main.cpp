// contactgrid: entry point. Exceptions become one message and a documented exit code:
// 0 ok, 1 validation FAIL, 2 usage, 3 bad input, 4 CUDA, 5 MPI, 6 I/O, 7 out of memory, 8 internal.
#include <cstdio>
#include <exception>
#include <new>

#include "cli.hpp"
#include "errors.hpp"

int main(int argc, char** argv) {
  try {
    return cg::run_cli(argc, argv);
  } catch (const cg::Error& e) {
    std::fprintf(stderr, "contactgrid: error: %s\n", e.what());
    return e.exit_code();
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "contactgrid: error: out of host memory\n");
    return 7;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "contactgrid: internal error: %s\n", e.what());
    return 8;
  }
}
