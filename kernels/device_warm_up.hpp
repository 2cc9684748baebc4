#pragma once
// DeviceWarmUp: a GPU made ready for a run while the run reads its scene. g++-safe public header.
//
// A new process pays for its device twice before its first detection finishes: the CUDA context's
// creation when its first engine is made, and each kernel's load at its first launch (CUDA loads
// kernels lazily; a detection's first launches cost tens of milliseconds inside its stages). A
// DeviceWarmUp does both on a thread of its own — the context of EngineOptions::device, then one
// small detection of each mode and shape kind still wanted (the run's options, so the same kernels
// launch), which also allocates the process's pinned transfer ring — while the caller reads its input.
// Once the caller knows its mode and shapes it calls keep_only(): the modes not chosen are skipped if
// not yet begun; wait() joins the thread. Errors stay on the thread (the run's own engine reports
// what the device refuses). Builds without CUDA, machines without a device, and
// CONTACTGRID_DEVICE_WARM_UP=0 start no thread.
//
//   cg::DeviceWarmUp warm(options.engine, cg::DeviceWarmUp::all_modes());  // before the read
//   ReadScene in = read_scene(...);
//   warm.keep_only(mode, in.has_shapes);
//   const double waited = warm.wait();                                    // before the engine
#include <atomic>
#include <thread>

#include "engine.hpp"
#include "precision.hpp"

namespace cg {

class DeviceWarmUp {
 public:
  // Bits of the modes to load, in the order the thread loads them.
  static constexpr unsigned bit(Precision p) { return 1u << static_cast<unsigned>(p); }
  static constexpr unsigned all_modes() {
    return bit(Precision::fp32) | bit(Precision::mixed) | bit(Precision::fp64);
  }

  // Starts the thread (see above) for the CUDA device of `options` (backend cpu: none). `modes`:
  // bit()s; `ellipsoids`: also the kernels of scenes with ellipsoids (a scene of both kinds).
  DeviceWarmUp(const EngineOptions& options, unsigned modes, bool ellipsoids = true);
  ~DeviceWarmUp();  // waits
  DeviceWarmUp(const DeviceWarmUp&) = delete;
  DeviceWarmUp& operator=(const DeviceWarmUp&) = delete;

  // Only `mode` from now on, and the kernels of the scene's kind: `ellipsoids`, a scene with
  // ellipsoids (every body through the shapes' kernels), else spheres alone.
  void keep_only(Precision mode, bool ellipsoids);
  // Joins the thread; returns the seconds the caller waited for it (0 when none ran or it had ended).
  double wait();
  // The thread's own seconds (0 when none ran; read after wait()).
  double seconds() const { return m_seconds; }
  // ... of which the context's creation.
  double context_seconds() const { return m_context; }

 private:
  void run(EngineOptions options);
  std::atomic<unsigned> m_modes;
  std::atomic<bool> m_spheres{true}, m_ellipsoids;
  double m_seconds = 0, m_context = 0;
  std::thread m_thread;
};

}  // namespace cg
