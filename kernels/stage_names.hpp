#pragma once
// The names of the engine's stages (both backends), in pipeline order ("upload" and "download": CUDA
// only): the names that StageTimes carries, made once from the typed stage ids of kernels/stage.hpp
// (internal). g++-safe public header.
#include <string>
#include <vector>

namespace cg {

const std::vector<std::string>& engine_stage_names();

}  // namespace cg
