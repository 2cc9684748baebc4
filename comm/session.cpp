// The MPI session (see session.hpp): laptop mode without a launcher, otherwise a duplicated
// communicator with MPI_ERRORS_RETURN and every call checked.
#include <cstdio>
#include <cstdlib>
#include <new>
#include <string>
#include <vector>

#include "mpi_detail.hpp"

namespace cg {

namespace detail {

void mpi_check(int rc, const char* call) {
  if (rc == MPI_SUCCESS) return;
  char text[MPI_MAX_ERROR_STRING] = {};
  int length = 0;
  if (MPI_Error_string(rc, text, &length) != MPI_SUCCESS) {
    std::snprintf(text, sizeof text, "MPI error code %d", rc);
  }
  throw CommFailure(std::string(call) + " failed: " + text);
}

}  // namespace detail

bool launched_by_mpi() {
  if (const char* force = std::getenv("CONTACTGRID_MPI")) {
    if (std::string(force) == "0") return false;
    if (std::string(force) == "1") return true;
  }
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMI_RANK", "PMIX_RANK"}) {
    if (std::getenv(name) != nullptr) return true;
  }
  return false;
}

[[noreturn]] void throw_by_exit_code(int exit_code, const std::string& message) {
  switch (exit_code) {
    case 2:
      throw UsageError(message);
    case 3:
      throw InputError(message);
    case 4:
      throw CudaError(message);
    case 5:
      throw MpiError(message);
    case 6:
      throw IoError(message);
    case 7:
      throw ResourceError(message);
    case 9:
      throw LimitError(message);
    default:
      if (exit_code > 128 && exit_code < 192) throw Stopped(exit_code - 128, message);
      throw Error(message);
  }
}

Session::Session(int* argc, char*** argv) : m_impl(std::make_unique<Impl>()) {
  if (!launched_by_mpi()) return;  // laptop mode: one rank, no MPI
  Impl& s = *m_impl;
  int initialised = 0;
  CG_MPI(MPI_Initialized(&initialised));
  if (!initialised) {
    int provided = 0;
    // MPI_Init_thread's failures are fatal under the default handler; checked anyway.
    CG_MPI(MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided));
    s.finalize = true;
  }
  s.mpi = true;
  CG_MPI(MPI_Comm_dup(MPI_COMM_WORLD, &s.comm));
  CG_MPI(MPI_Comm_set_errhandler(s.comm, MPI_ERRORS_RETURN));
  CG_MPI(MPI_Comm_rank(s.comm, &s.rank));
  CG_MPI(MPI_Comm_size(s.comm, &s.size));
  MPI_Comm node = MPI_COMM_NULL;
  CG_MPI(MPI_Comm_split_type(s.comm, MPI_COMM_TYPE_SHARED, s.rank, MPI_INFO_NULL, &node));
  CG_MPI(MPI_Comm_rank(node, &s.local_rank));
  CG_MPI(MPI_Comm_size(node, &s.local_size));
  CG_MPI(MPI_Comm_free(&node));
}

Session::~Session() {
  // No throwing from here: return codes are ignored, MPI is shutting down anyway.
  if (m_impl->comm != MPI_COMM_NULL) MPI_Comm_free(&m_impl->comm);
  if (m_impl->finalize) {
    int finalised = 0;
    MPI_Finalized(&finalised);
    if (!finalised) MPI_Finalize();
  }
}

bool Session::uses_mpi() const { return m_impl->mpi; }
int Session::rank() const { return m_impl->rank; }
int Session::size() const { return m_impl->size; }
int Session::local_rank() const { return m_impl->local_rank; }
int Session::local_size() const { return m_impl->local_size; }

int Session::device_for(int device_count) const {
  return device_count > 0 ? m_impl->local_rank % device_count : -1;
}

std::string Session::prefix() const {
  return "[rank " + std::to_string(m_impl->rank) + "/" + std::to_string(m_impl->size) + "] ";
}

void Session::abort(int code, const std::string& message) const {
  std::fprintf(stderr, "%s%s\n", prefix().c_str(), message.c_str());
  std::fflush(stderr);
  if (m_impl->mpi) MPI_Abort(m_impl->comm != MPI_COMM_NULL ? m_impl->comm : MPI_COMM_WORLD, code);
  std::exit(code);
}

void Session::barrier() const {
  if (m_impl->mpi) CG_MPI(MPI_Barrier(m_impl->comm));
}

void Session::agree(std::exception_ptr error, const std::string& stage) const {
  if (!m_impl->mpi) {
    if (error) std::rethrow_exception(error);
    return;
  }
  int code = 0;
  std::string what;
  if (error) {
    try {
      std::rethrow_exception(error);
    } catch (const Error& e) {
      code = e.exit_code();
      what = e.what();
    } catch (const std::bad_alloc&) {
      code = 7;
      what = "out of host memory";
    } catch (const std::exception& e) {
      code = 8;
      what = e.what();
    } catch (...) {
      code = 8;
      what = "unknown exception";
    }
  }
  const Impl& s = *m_impl;
  int mine = error ? s.rank : s.size, first = s.size;
  CG_MPI(MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, s.comm));
  if (first == s.size) return;
  // The lowest failing rank tells everyone its exit code and message.
  long long header[2] = {code, static_cast<long long>(what.size())};
  CG_MPI(MPI_Bcast(header, 2, MPI_LONG_LONG, first, s.comm));
  std::string text(static_cast<std::size_t>(header[1]), '\0');
  if (s.rank == first) text = what;
  if (!text.empty()) {
    CG_MPI(
        MPI_Bcast(text.data(), detail::to_mpi_count(text.size(), "error message"), MPI_CHAR, first, s.comm));
  }
  throw_by_exit_code(static_cast<int>(header[0]), "[rank " + std::to_string(first) + "/" +
                                                      std::to_string(s.size) + "] " + stage + ": " + text);
}

std::string Session::broadcast(const std::string& text, int root) const {
  if (!m_impl->mpi) return text;
  unsigned long long n = text.size();
  CG_MPI(MPI_Bcast(&n, 1, MPI_UNSIGNED_LONG_LONG, root, m_impl->comm));
  std::string out = m_impl->rank == root ? text : std::string(static_cast<std::size_t>(n), '\0');
  if (n > 0) {
    CG_MPI(MPI_Bcast(out.data(), detail::to_mpi_count(n, "broadcast"), MPI_CHAR, root, m_impl->comm));
  }
  return out;
}

bool Session::all(bool value) const {
  if (!m_impl->mpi) return value;
  int v = value ? 1 : 0, r = 0;
  CG_MPI(MPI_Allreduce(&v, &r, 1, MPI_INT, MPI_MIN, m_impl->comm));
  return r != 0;
}

double Session::max(double value) const {
  if (!m_impl->mpi) return value;
  double r = 0;
  CG_MPI(MPI_Allreduce(&value, &r, 1, MPI_DOUBLE, MPI_MAX, m_impl->comm));
  return r;
}

unsigned long long Session::sum(unsigned long long value) const {
  if (!m_impl->mpi) return value;
  unsigned long long r = 0;
  CG_MPI(MPI_Allreduce(&value, &r, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, m_impl->comm));
  return r;
}

}  // namespace cg
