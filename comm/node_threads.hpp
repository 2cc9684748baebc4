#pragma once
// The rank's share of the node's host threads. g++-safe public header.

namespace cg {

class Session;

// Host threads of this rank (its comm loops and its engine): `requested` when > 0, else an equal
// share of the node's hardware threads among the ranks on the node. Each rank taking every core would
// oversubscribe a node P times under `mpirun --bind-to none`: P OpenMP teams of one thread per core,
// whose barriers wait for descheduled threads.
int host_threads(int requested, const Session& session);

// For one run, this rank's share is also OpenMP's default team size, so that every parallel loop
// that asks omp_get_max_threads() (the scene reader, compute_bounds, the CUDA download's copy, ...)
// takes the share too. Without it, two ranks on a 32-thread node run 32-thread loops each, and their
// spinning barriers make the np 2 read several times slower than np 1's (BENCHMARKS.md §4).
class DefaultTeam {
 public:
  explicit DefaultTeam(int threads);
  ~DefaultTeam();
  DefaultTeam(const DefaultTeam&) = delete;
  DefaultTeam& operator=(const DefaultTeam&) = delete;

 private:
  int m_saved;
};

}  // namespace cg
