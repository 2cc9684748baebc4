#include "upload_pack.hpp"

#include <omp.h>

namespace cg::detail {

void pack_upload_spheres(const Vec3<double>* position, const double* radius, const Vec3<double>& origin,
                         std::size_t begin, std::size_t end, Sphere<float>* dst, int threads) {
  const std::size_t n = end > begin ? end - begin : 0;
  const int nt = n < (std::size_t(1) << 15) ? 1 : (threads > 0 ? threads : omp_get_max_threads());
#pragma omp parallel for num_threads(nt) schedule(static) if (nt > 1)
  for (std::size_t k = 0; k < n; ++k) {
    const Vec3<double> p = position[begin + k];
    dst[k] = {static_cast<float>(p.x - origin.x), static_cast<float>(p.y - origin.y),
              static_cast<float>(p.z - origin.z), static_cast<float>(radius[begin + k])};
  }
}

}  // namespace cg::detail
