#pragma once
// The summary stage of `contactgrid detect` (rank 0, silenced by -q): what ran, with its counts and the
// per-stage times (maximum over ranks).
#include <cstdint>

#include "io/contact_file.hpp"
#include "run/distributed_detect.hpp"

namespace cg {

// info: the run as the contact file records it (its precision_choice, when --precision auto chose,
// is printed as the second line); times: the run's and the write's.
template <class Real>
void print_summary(const RunInfo& info, const RunTimes& times, std::uint64_t contacts,
                   const DistributedResult<Real>& r);

}  // namespace cg
