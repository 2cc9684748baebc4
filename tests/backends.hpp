#pragma once
// One test body for both backends and both precisions: typed test configurations. CUDA cases skip,
// visibly, when no GPU is present (CI has none).
#include <gtest/gtest.h>

#include "engine.hpp"

namespace cg::test {

template <class R, Backend B>
struct Config {
  using Real = R;
  static constexpr Backend backend = B;
};
using AllConfigs = ::testing::Types<Config<double, Backend::cpu>, Config<float, Backend::cpu>,
                                    Config<double, Backend::cuda>, Config<float, Backend::cuda>>;

struct ConfigNames {
  template <class T>
  static std::string GetName(int) {
    return std::string(to_string(T::backend)) + (sizeof(typename T::Real) == 4 ? "_fp32" : "_fp64");
  }
};

// One test body per backend, the precision modes chosen inside the body.
template <Backend B>
struct OnBackend {
  static constexpr Backend backend = B;
};
using BackendTypes = ::testing::Types<OnBackend<Backend::cpu>, OnBackend<Backend::cuda>>;
struct BackendTypeNames {
  template <class T>
  static std::string GetName(int) {
    return to_string(T::backend);
  }
};

#define CG_SKIP_WITHOUT_BACKEND(cfg)                                       \
  do {                                                                     \
    if ((cfg::backend) == ::cg::Backend::cuda && !::cg::cuda_available())  \
      GTEST_SKIP() << "no CUDA device in this process: CUDA case skipped"; \
  } while (0)

}  // namespace cg::test
