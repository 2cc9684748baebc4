// libFuzzer harness over every reader of an input file: the scene readers (detect, validate), the
// contact reader (validate) and the dataset inspection of compare. Built and run by
// tests/fuzz/build_and_run.sh (not part of the default build). The input is written to a file in
// /dev/shm (the readers take paths) and read by each reader; an InputError is the expected outcome
// for damaged files, anything else (a crash, a sanitizer report, an allocation over -malloc_limit_mb,
// a timeout, another exception) is a finding.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include "errors.hpp"
#include "io/contact_file.hpp"
#include "io/inspect.hpp"
#include "io/scene_file.hpp"

namespace {

const std::string& input_path() {
  static const std::string path = "/dev/shm/cg_fuzz_readers." + std::to_string(::getpid()) + ".h5";
  return path;
}

template <class F>
void expect_clean(F&& read) {
  try {
    read();
  } catch (const cg::InputError&) {
    // a damaged file, told as such
  } catch (const cg::UsageError&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string& path = input_path();
  {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (f == nullptr) return 0;
    std::fwrite(data, 1, size, f);
    std::fclose(f);
  }
  // One open per reader where one suffices: read_scene_shape and read_scene_rows share read_scene's
  // path (open_scene), and compare reads every dataset alike, so three of them stand for all.
  expect_clean([&] { cg::read_scene(path); });
  expect_clean([&] { cg::read_contacts(path); });
  for (const char* dataset : {"/contacts/id_a", "/contacts/position_on_a", "/contacts/distance"}) {
    expect_clean([&] {
      if (cg::inspect_dataset(path, dataset)) cg::read_dataset_bytes(path, dataset);
    });
  }
  return 0;
}
