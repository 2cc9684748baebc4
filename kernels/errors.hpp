#pragma once
// Typed exceptions used across the project; main() maps them to documented exit codes
// (docs/ERRORS.md): 0 ok, 1 validation FAIL, 2 usage, 3 input, 4 CUDA, 5 MPI, 6 I/O, 7 resources
// (memory), 8 internal, 9 a limit the user set (--max-pair-tests), 128 + N stopped by signal N.
#include <stdexcept>
#include <string>

namespace cg {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
  virtual int exit_code() const { return 8; }
};
class UsageError : public Error {
 public:
  using Error::Error;
  int exit_code() const override { return 2; }
};
class InputError : public Error {  // bad scene data: names the file, dataset and row
 public:
  using Error::Error;
  int exit_code() const override { return 3; }
};
class CudaError : public Error {
 public:
  using Error::Error;
  int exit_code() const override { return 4; }
};
class MpiError : public Error {
 public:
  using Error::Error;
  int exit_code() const override { return 5; }
};
class IoError : public Error {  // cannot read/write a file (not a data problem)
 public:
  using Error::Error;
  int exit_code() const override { return 6; }
};
class ResourceError : public Error {  // not enough (device) memory: says how much is needed
 public:
  using Error::Error;
  int exit_code() const override { return 7; }
};
class LimitError : public Error {  // the work would exceed a limit the user set: says how much
 public:
  using Error::Error;
  int exit_code() const override { return 9; }
};
class Stopped : public Error {  // a signal stopped the run (src/run/stop.hpp)
 public:
  Stopped(int signal, const std::string& what) : Error(what), m_signal(signal) {}
  int signal() const { return m_signal; }
  int exit_code() const override { return 128 + m_signal; }

 private:
  int m_signal;
};

}  // namespace cg
