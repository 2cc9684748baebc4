#pragma once
// The CUDA backend of the granular dynamics (kernels/dem.hpp): its DEVICE state, shared by its stages
// (dem_integrate.cuh, dem_forces.cuh, dem_sums.cuh, dem_energy.cuh), sequenced by dem_backend.cu.
// Every kernel runs on the legacy default stream: the engine's own (blocking) stream is ordered
// after it, and the engine returns with its contacts complete, so the stages and the engine's
// detection follow each other with no extra synchronisation.
#include <cstdint>

#include "core/dem_step.hpp"
#include "cuda/device_buffer.cuh"
#include "cuda/thrust_alloc.cuh"
#include "dem.hpp"

namespace cg::detail {

template <class T>
using DemBuffer = cuda::DeviceBuffer<T>;

class CudaDem {
 public:
  int device = 0;
  std::size_t count = 0;
  bool shapes = false;  // shape rows (ellipsoids present)
  // bodies
  DemBuffer<Vec3<double>> position, velocity, omega, momentum, force, torque, semi_axes;
  DemBuffer<Quat<double>> orientation;
  DemBuffer<dem::BodyProps> props;
  DemBuffer<Shape> shape;
  DemBuffer<double> radius;
  // contacts: terms of the step, springs and normals of this step and the last (current: the last)
  DemBuffer<Vec3<double>> contact_force, torque_a, torque_b, xi[2], normal[2];
  DemBuffer<double> contact_energy;
  int current = 0;
  // the rows by B, the begins of each body's rows, walls, their springs and energies
  DemBuffer<std::uint32_t> b_keys[2], by_b[2], a_begin, b_begin;
  DemBuffer<std::byte> sort_temp;
  DemBuffer<dem::Wall> walls;
  int wall_count = 0;
  DemBuffer<Vec3<double>> wall_xi;
  DemBuffer<double> wall_energy, partials;
  ThrustAllocator thrust;

  dem::BodyArrays arrays() const {
    return {position.data(),  velocity.data(),    omega.data(),
            momentum.data(),  orientation.data(), force.data(),
            torque.data(),    props.data(),       shapes ? shape.data() : nullptr,
            semi_axes.data(), radius.data(),      count};
  }
};

}  // namespace cg::detail
