// test_fault.cpp: the test-only fault knob (see test_fault.hpp).
#include "run/test_fault.hpp"

#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>

#include "errors.hpp"
#include "run/stop.hpp"

namespace cg {
namespace {

struct Fault {
  std::string action, stage;
  int rank = -1;  // -1: every rank
};

// The knob, parsed once; no action when unset. UsageError naming it when malformed.
const Fault& fault() {
  static const Fault f = [] {
    Fault out;
    const char* text = std::getenv("CONTACTGRID_TEST_FAULT");
    if (text == nullptr || *text == '\0') return out;
    const std::string s = text;
    const auto at = s.find('@'), colon = s.find(':');
    out.action = s.substr(0, at);
    out.stage =
        at == std::string::npos ? "" : s.substr(at + 1, colon == std::string::npos ? colon : colon - at - 1);
    if (colon != std::string::npos) out.rank = std::atoi(s.c_str() + colon + 1);
    const bool action_ok = out.action == "wait" || out.action == "hang" || out.action == "exit" ||
                           out.action == "kill" || out.action == "oom" || out.action == "device";
    const bool stage_ok = out.stage == "read" || out.stage == "exchange" || out.stage == "detect" ||
                          out.stage == "piece" || out.stage == "gather" || out.stage == "write";
    if (!action_ok || !stage_ok)
      throw UsageError(
          "CONTACTGRID_TEST_FAULT=" + s +
          ": expected <wait|hang|exit|kill|oom|device>@<read|exchange|detect|piece|gather|write>[:<rank>]");
    return out;
  }();
  return f;
}

}  // namespace

void fault_point(const char* stage, int rank) {
  const Fault& f = fault();
  if (f.action.empty() || f.stage != stage || (f.rank >= 0 && f.rank != rank)) return;
  std::fprintf(stderr, "contactgrid: test fault: rank %d %s at %s\n", rank, f.action.c_str(), stage);
  std::fflush(stderr);
  using namespace std::chrono_literals;
  if (f.action == "exit") std::exit(1);
  if (f.action == "oom") throw ResourceError(std::string("test fault: out of device memory at ") + stage);
  if (f.action == "device") throw CudaError(std::string("test fault: a device error at ") + stage);
  if (f.action == "kill") ::raise(SIGKILL);
  const auto end = std::chrono::steady_clock::now() + 600s;
  while (std::chrono::steady_clock::now() < end) {
    if (f.action == "wait") stop_point();
    std::this_thread::sleep_for(10ms);
  }
}

}  // namespace cg
