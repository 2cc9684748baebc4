// Plain CUDA device memory (device_memory.hpp): the CUDA runtime's host API, no kernels.
#include "device_memory.hpp"

#include <string>

#include "errors.hpp"

#if defined(CONTACTGRID_HAVE_CUDA)
#include <cuda_runtime.h>

namespace cg::device_memory {
namespace {
void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess) throw CudaError(std::string(what) + ": " + cudaGetErrorString(e));
}
}  // namespace

void* allocate(std::size_t bytes) {
  void* p = nullptr;
  const cudaError_t e = cudaMalloc(&p, bytes > 0 ? bytes : 1);
  if (e == cudaErrorMemoryAllocation) {
    cudaGetLastError();  // the failure is reported here, not by the next CUDA call
    throw ResourceError("out of device memory: " + std::to_string(bytes) + " bytes asked for");
  }
  check(e, "cudaMalloc");
  return p;
}

void release(void* p) noexcept {
  if (p) cudaFree(p);
}

void copy_to_device(void* device_dst, const void* host_src, std::size_t bytes) {
  if (bytes > 0)
    check(cudaMemcpy(device_dst, host_src, bytes, cudaMemcpyHostToDevice), "cudaMemcpy to device");
}

void copy_to_host(void* host_dst, const void* device_src, std::size_t bytes) {
  if (bytes > 0) check(cudaMemcpy(host_dst, device_src, bytes, cudaMemcpyDeviceToHost), "cudaMemcpy to host");
}

void synchronize_stream(std::uintptr_t stream) {
  cudaStream_t s = stream == 1   ? cudaStreamLegacy
                   : stream == 2 ? cudaStreamPerThread
                                 : reinterpret_cast<cudaStream_t>(stream);
  check(cudaStreamSynchronize(s), "cudaStreamSynchronize (the input arrays' stream)");
}

bool is_device_pointer(const void* p) {
  cudaPointerAttributes a{};
  if (cudaPointerGetAttributes(&a, p) != cudaSuccess) {
    cudaGetLastError();
    return false;
  }
  return a.type == cudaMemoryTypeDevice || a.type == cudaMemoryTypeManaged;
}

int device_of(const void* p) {
  cudaPointerAttributes a{};
  if (p && cudaPointerGetAttributes(&a, p) == cudaSuccess &&
      (a.type == cudaMemoryTypeDevice || a.type == cudaMemoryTypeManaged))
    return a.device;
  cudaGetLastError();
  int device = 0;
  check(cudaGetDevice(&device), "cudaGetDevice");
  return device;
}

}  // namespace cg::device_memory

#else

namespace cg::device_memory {
namespace {
[[noreturn]] void no_cuda() {
  throw CudaError("this contactgrid was built without CUDA (rebuild with nvcc present)");
}
}  // namespace
void* allocate(std::size_t) { no_cuda(); }
void release(void*) noexcept {}
void copy_to_device(void*, const void*, std::size_t) { no_cuda(); }
void copy_to_host(void*, const void*, std::size_t) { no_cuda(); }
void synchronize_stream(std::uintptr_t) { no_cuda(); }
bool is_device_pointer(const void*) { return false; }
int device_of(const void*) { no_cuda(); }
}  // namespace cg::device_memory

#endif
