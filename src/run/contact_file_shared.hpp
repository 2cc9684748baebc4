#pragma once
// One contact file written by every rank of a Session at once. Uses no MPI of its own: only Session's
// collectives (agree, sum, max, broadcast of the file layout).
//
// Each rank holds rows [first_row, first_row + slice.size()) of the K sorted contacts (what
// distributed_detect leaves, either mode; with ContactOutput::ranks every rank has a share):
//   (a) rank 0 creates "<path>.tmp.<pid>" with every /contacts dataset of K rows, allocated and
//       unwritten (src/io/contact_file: create_contact_file), and broadcasts its layout (the file's name and
//       each dataset's offset);
//   (b) every rank writes its rows at their offsets with pwrite, by `threads` threads
//       (write_contact_rows) — no rank waits for another's data, no HDF5 call;
//   (c) rank 0 records the root attributes (docs/FORMAT.md §2, with info.times plus "write": the maximum
//       over ranks of phases a–b) and renames the file over `path` (commit_contact_file).
// Every phase ends with Session::agree (stage "write"): a failure on any rank makes every rank throw
// the same exception, rank 0 removes the temporary, and no output appears. The slices must tile
// [0, K): checked before the file is created (sum of the sizes == K, each inside [0, K)).
// With one rank (laptop mode) this is write_contacts with `threads` writers.
#include <cstdint>
#include <string>

#include "engine.hpp"
#include "io/contact_file.hpp"
#include "session.hpp"

namespace cg {

// Collective over `session`. Appends {"write", seconds} to info.times (every rank) and returns it.
template <class Real>
double write_contacts_distributed(Session& session, const std::string& path, const Contacts<Real>& slice,
                                  std::uint64_t first_row, std::uint64_t total_rows, RunInfo& info,
                                  int threads = 0);

extern template double write_contacts_distributed<float>(Session&, const std::string&, const Contacts<float>&,
                                                         std::uint64_t, std::uint64_t, RunInfo&, int);
extern template double write_contacts_distributed<double>(Session&, const std::string&,
                                                          const Contacts<double>&, std::uint64_t,
                                                          std::uint64_t, RunInfo&, int);

}  // namespace cg
