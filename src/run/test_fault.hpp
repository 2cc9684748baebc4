#pragma once
// A test-only fault knob: CONTACTGRID_TEST_FAULT=<action>@<stage>[:<rank>] makes rank <rank> (every
// rank when omitted) misbehave when it reaches <stage> of `detect`, so that the tests of signals and
// dying ranks (tests/unit/test_stop.cpp, tests/cli/dying_ranks.sh) find a run exactly where they
// want it. Stages: read (after the rank's rows are read), exchange (before the ghosts are exchanged),
// detect (before the engine runs), piece (under --memory-limit: before the second detection of a
// piece, decomposition/pieces.hpp, the first piece's rows already handed on), gather (before the contacts are
// collected), write (the output's temporary exists, no row written yet). Actions:
//   wait  sleep up to 600 s, stopping at a signal like any stage (stop points every 10 ms)
//   hang  sleep 600 s without a stop point (a stage that never looks: the grace or a second signal
//         ends it)
//   exit  std::exit(1) at once, without finalising MPI
//   kill  SIGKILL itself
//   oom   throw ResourceError (exit code 7), as an engine out of device memory does
//   device  throw CudaError (exit code 4), as a failing device does
// The rank says "contactgrid: test fault: rank R <action> at <stage>" on stderr first. Unset (the
// normal case), fault_point costs one comparison.
namespace cg {

// Called by the pipeline at each stage above; `rank` is the caller's rank.
void fault_point(const char* stage, int rank);

}  // namespace cg
