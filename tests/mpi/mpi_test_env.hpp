#pragma once
// The environment of contactgrid_mpi_tests (set up by mpi_main.cpp): the process's Session and a
// temporary directory shared by all ranks (created by rank 0, removed at the end).
#include <string>

#include "session.hpp"

namespace cg::testing {

Session& session();
const std::string& shared_temp_dir();

}  // namespace cg::testing
