// The rank's share of the node's threads (see node_threads.hpp).
#include "node_threads.hpp"

#include <omp.h>

#include <algorithm>

#include "session.hpp"

namespace cg {

int host_threads(int requested, const Session& session) {
  if (requested > 0) return requested;
  static const int node_threads = omp_get_max_threads();  // before any run set the default (below)
  return std::max(1, node_threads / std::max(1, session.local_size()));
}

DefaultTeam::DefaultTeam(int threads) : m_saved(omp_get_max_threads()) { omp_set_num_threads(threads); }
DefaultTeam::~DefaultTeam() { omp_set_num_threads(m_saved); }

}  // namespace cg
