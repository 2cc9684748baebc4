#pragma once
// Internal to comm/: the MPI side of Session and checked-call helpers. Includes <mpi.h>; never
// include it from outside comm/.
#include <mpi.h>

#include <climits>
#include <cstdint>
#include <string>
#include <type_traits>
#include <vector>

#include "session.hpp"

namespace cg {

struct Session::Impl {
  bool mpi = false;               // MPI mode (MPI_Init_thread called by us or before us)
  bool finalize = false;          // we initialised MPI, so we finalise it
  MPI_Comm comm = MPI_COMM_NULL;  // duplicate of MPI_COMM_WORLD, MPI_ERRORS_RETURN
  int rank = 0, size = 1, local_rank = 0, local_size = 1;
};

namespace detail {

// Throws CommFailure("<call> failed: <MPI error string>") unless rc == MPI_SUCCESS.
void mpi_check(int rc, const char* call);
#define CG_MPI(call) ::cg::detail::mpi_check((call), #call)

// A contiguous MPI datatype of sizeof(T) bytes (trivially copyable T, homogeneous nodes), freed on
// destruction, so counts are in elements of T, not bytes.
class RecordType {
 public:
  explicit RecordType(std::size_t bytes) {
    CG_MPI(MPI_Type_contiguous(static_cast<int>(bytes), MPI_BYTE, &m_type));
    CG_MPI(MPI_Type_commit(&m_type));
  }
  ~RecordType() {
    if (m_type != MPI_DATATYPE_NULL) MPI_Type_free(&m_type);
  }
  RecordType(const RecordType&) = delete;
  RecordType& operator=(const RecordType&) = delete;
  MPI_Datatype get() const { return m_type; }

 private:
  MPI_Datatype m_type = MPI_DATATYPE_NULL;
};

// MPI counts and displacements are int: converts, or throws CommFailure naming what overflowed.
inline int to_mpi_count(std::uint64_t n, const char* what) {
  if (n > static_cast<std::uint64_t>(INT_MAX)) {
    throw CommFailure(std::string(what) + ": " + std::to_string(n) +
                      " elements exceed the MPI count limit (2^31 - 1)");
  }
  return static_cast<int>(n);
}

}  // namespace detail
}  // namespace cg
