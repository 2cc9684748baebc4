#pragma once
// A stage's local work, then every rank agrees on whether any rank failed (Session::agree): either
// every rank returns, or every rank throws the same error "[rank r/N] <stage>: <cause>".
// g++-safe public header.
#include <exception>

#include "session.hpp"

namespace cg {

template <class F>
void agreed_stage(const Session& session, const char* stage, F&& work) {
  std::exception_ptr error;
  try {
    work();
  } catch (...) {
    error = std::current_exception();
  }
  session.agree(error, stage);
}

}  // namespace cg
