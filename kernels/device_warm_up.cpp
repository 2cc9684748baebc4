#include "device_warm_up.hpp"

#include <cstdlib>
#include <vector>

#include "timing.hpp"

namespace cg {
namespace {

// CONTACTGRID_DEVICE_WARM_UP=0: no thread (measurement knob: the first detection loads its kernels).
bool warm_up_wanted() {
  const char* v = std::getenv("CONTACTGRID_DEVICE_WARM_UP");
  return !(v && v[0] == '0');
}

// The small scene: a cubic lattice of 2^17 bodies of radius 1 at spacing 1.9, so that every
// neighbour touches (the narrow stage writes rows) and the input crosses the size from which the
// upload streams through the pinned ring (1 MiB). With `ellipsoids` every other body is an
// ellipsoid of semi-axes (1, 0.7, 0.5), turned a little.
struct WarmScene {
  std::vector<Vec3<double>> position;
  std::vector<double> radius;
  std::vector<Shape> shape;
  std::vector<Vec3<double>> semi_axes;
  std::vector<Quat<double>> orientation;

  explicit WarmScene(bool ellipsoids) {
    constexpr int side = 51;  // 51^3 = 132 651 bodies
    for (int i = 0; i < side; ++i)
      for (int j = 0; j < side; ++j)
        for (int k = 0; k < side; ++k) {
          position.push_back({1.9 * i, 1.9 * j, 1.9 * k});
          radius.push_back(1.0);
        }
    if (!ellipsoids) return;
    const std::size_t n = radius.size();
    shape.resize(n);
    semi_axes.assign(n, Vec3<double>{1.0, 0.7, 0.5});
    orientation.assign(n, Quat<double>{0.99500416527802582, 0.09983341664682815, 0, 0});  // 0.2 rad about x
    for (std::size_t b = 0; b < n; ++b) shape[b] = b % 2 ? Shape::ellipsoid : Shape::sphere;
  }
  BodiesView view() const {
    BodiesView v{position, radius, {}, {}};
    if (!shape.empty()) {
      v.shape = shape;
      v.semi_axes = semi_axes;
      v.orientation = orientation;
    }
    return v;
  }
};

// One detection of `scene` in `mode` with the run's options (no callbacks, no limits on the work).
void detect_once(EngineOptions options, Precision mode, const WarmScene& scene) {
  options.threads = 1;  // the host's share of a small detection: not the cores the caller reads with
  options.on_pair_estimate = {};
  options.on_pair_progress = {};
  options.max_pair_tests = 0;
  options.skin = 0;
  options.skin_auto = false;
  options.history = false;
  options.fp32_broad_phase = mode == Precision::mixed;
  if (mode == Precision::fp32)
    Engine<float>(options).detect(scene.view());
  else
    Engine<double>(options).detect(scene.view());
}

}  // namespace

DeviceWarmUp::DeviceWarmUp(const EngineOptions& options, unsigned modes, bool ellipsoids)
    : m_modes(modes), m_ellipsoids(ellipsoids) {
  if (options.backend == Backend::cpu || !warm_up_wanted() || !cuda_available()) return;
  m_thread = std::thread([this, options] { run(options); });
}

DeviceWarmUp::~DeviceWarmUp() { wait(); }

void DeviceWarmUp::keep_only(Precision mode, bool ellipsoids) {
  m_modes.store(m_modes.load() & bit(mode));
  m_spheres.store(!ellipsoids);  // a scene with ellipsoids runs every body through the shapes' kernels
  m_ellipsoids.store(m_ellipsoids.load() && ellipsoids);
}

double DeviceWarmUp::wait() {
  if (!m_thread.joinable()) return 0;
  const auto t0 = WallClock::now();
  m_thread.join();
  return seconds_since(t0);
}

void DeviceWarmUp::run(EngineOptions options) {
  const auto t0 = WallClock::now();
  options.backend = Backend::cuda;
  try {
    Engine<float> context(options);  // the device's context (the engine's stream)
    m_context = seconds_since(t0);
    // the modes a run most often picks first: --precision auto's usual pick on a GPU is mixed
    const WarmScene spheres(false);
    for (Precision mode : {Precision::mixed, Precision::fp64, Precision::fp32}) {
      if (!(m_modes.load() & bit(mode))) continue;
      if (m_spheres.load()) detect_once(options, mode, spheres);
      if (m_ellipsoids.load() && m_modes.load() & bit(mode)) detect_once(options, mode, WarmScene(true));
    }
  } catch (...) {  // the run's own engine meets the same device and reports it
  }
  m_seconds = seconds_since(t0);
}

}  // namespace cg
