// Contacts: allocation of the result vectors.
#include "contacts.hpp"

namespace cg {

template <class Real>
void Contacts<Real>::reserve(std::size_t k, bool with_full) {
  id_a.reserve(k);
  id_b.reserve(k);
  position_on_a.reserve(k);
  position_on_b.reserve(k);
  normal_on_b.reserve(k);
  distance.reserve(k);
  if (with_full) {
    local_point_a.reserve(k);
    local_point_b.reserve(k);
    lateral_friction_dir1.reserve(k);
    lateral_friction_dir2.reserve(k);
  }
}

template <class Real>
void Contacts<Real>::resize(std::size_t k, bool with_full) {
  reserve(k, with_full);  // exact: growing by resize alone may over-allocate a non-empty vector
  full = with_full;
  id_a.resize(k);
  id_b.resize(k);
  position_on_a.resize(k);
  position_on_b.resize(k);
  normal_on_b.resize(k);
  distance.resize(k);
  const std::size_t kf = with_full ? k : 0;
  local_point_a.resize(kf);
  local_point_b.resize(kf);
  lateral_friction_dir1.resize(kf);
  lateral_friction_dir2.resize(kf);
}
template struct Contacts<float>;
template struct Contacts<double>;

}  // namespace cg
