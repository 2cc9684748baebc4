#pragma once
// The environment of contactgrid_mpi_tests (set up by mpi_main.cpp): the process's Session and a
// temporary directory shared by all ranks (created by rank 0, removed at the end).
#include <string>

#include "scene/scene.hpp"
#include "session.hpp"

namespace cg::testing {

Session& session();
const std::string& shared_temp_dir();

// `name` inside the shared directory.
std::string shared_path(const std::string& name);
// Collective: rank 0 writes `scene` as <shared dir>/<name>.h5 (an error there is every rank's error);
// returns the path once the file is complete.
std::string write_shared(const std::string& name, const Scene& scene);

}  // namespace cg::testing
