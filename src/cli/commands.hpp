#pragma once
// The small commands of the executable: compare and generate (the CLI parses, these run).
#include <string>

#include "scene/generate.hpp"

namespace cg {

// Compares the /contacts datasets of two contact files byte for byte (what `mpirun -np P` must
// reproduce from the single-rank run). Returns 0 when identical, 1 otherwise (and says where).
int run_compare(const std::string& a, const std::string& b);

// Writes the scene `options` describe to `path`; prints one line unless `quiet`. Returns 0.
int run_generate(const std::string& path, const GenerateOptions& options, bool quiet);

}  // namespace cg
