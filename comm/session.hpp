#pragma once
// The MPI session of one contactgrid process. g++-safe public header: does not include <mpi.h>
// (comm/ is the only folder that does, in its .cpp files and comm/mpi_detail.hpp).
//
// Two modes, chosen once at construction:
//   laptop mode  the process was not started by an MPI launcher (no OMPI_COMM_WORLD_SIZE, PMI_SIZE,
//                PMI_RANK or PMIX_RANK in the environment): MPI is NOT initialised, the session is one
//                rank of one, and every collective below is a local no-op. `contactgrid detect` on a
//                laptop needs no mpirun.
//   MPI mode     MPI_Init_thread (FUNNELED: only the main thread calls MPI; the engine's OpenMP threads
//                never do), MPI_COMM_WORLD duplicated, MPI_ERRORS_RETURN on the duplicate, every call
//                checked (CommFailure with the call's name and MPI's error string).
// The environment variable CONTACTGRID_MPI=0 forces laptop mode (e.g. a child process of an MPI job
// that inherits the launcher's variables), CONTACTGRID_MPI=1 forces MPI mode.
//
// Invariants: 0 <= rank() < size(); 0 <= local_rank() < local_size() <= size(); at most one Session
// per process (MPI can be initialised once); MPI is finalised by the destructor of the Session that
// initialised it.
#include <exception>
#include <memory>
#include <string>

#include "errors.hpp"

namespace cg {

// An MPI call failed: the state of the communication is unknown and other ranks may be waiting in a
// collective, so the caller must not continue with communication (distributed_detect turns it into
// Session::abort). Errors that all ranks have agreed on (Session::agree) are NOT CommFailures.
class CommFailure : public MpiError {
 public:
  using MpiError::MpiError;
};

class Session {
 public:
  // argc/argv may be null. Throws MpiError if MPI cannot be initialised.
  Session(int* argc = nullptr, char*** argv = nullptr);
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  bool uses_mpi() const;  // false in laptop mode
  int rank() const;
  int size() const;
  int local_rank() const;  // rank among the processes of this node (MPI_COMM_TYPE_SHARED)
  int local_size() const;

  // The GPU of this rank: local_rank() % device_count, or -1 when device_count <= 0.
  int device_for(int device_count) const;

  // "[rank r/N] " — the prefix of every rank-aware message.
  std::string prefix() const;

  // Prints "[rank r/N] message" to stderr and ends the whole job: MPI_Abort(code) in MPI mode (so no
  // rank hangs in a collective), std::exit(code) in laptop mode.
  [[noreturn]] void abort(int code, const std::string& message) const;

  // ---- collectives over the session's communicator (every rank must call them) ----------------
  void barrier() const;
  // Every rank learns whether any rank failed a stage. No rank failed: returns. Otherwise every rank
  // throws the same exception: the type of the lowest failing rank's error (by its exit code:
  // UsageError, InputError, CudaError, MpiError, IoError, ResourceError, LimitError, Stopped, else
  // Error) with the message
  // "[rank r/N] <stage>: <what>". In laptop mode the error itself is rethrown.
  // Throws CommFailure if the agreement itself cannot be communicated.
  void agree(std::exception_ptr error, const std::string& stage) const;
  std::string broadcast(const std::string& text, int root = 0) const;
  bool all(bool value) const;      // logical and over ranks
  double max(double value) const;  // maximum over ranks
  unsigned long long sum(unsigned long long value) const;

  struct Impl;  // defined in comm/mpi_detail.hpp
  const Impl& impl() const { return *m_impl; }

 private:
  std::unique_ptr<Impl> m_impl;
};

// True when the environment says an MPI launcher started this process (see Session).
bool launched_by_mpi();

// Rethrows an error as the typed exception of its exit code (used by Session::agree).
[[noreturn]] void throw_by_exit_code(int exit_code, const std::string& message);

}  // namespace cg
