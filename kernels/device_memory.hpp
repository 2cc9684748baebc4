#pragma once
// Plain CUDA device memory for callers that hold no GPU array library: the Python module's DeviceArray
// (an object of our own that exposes __cuda_array_interface__) and the wait on a caller's stream before
// the engine reads its arrays. g++-safe; in builds without CUDA every function but is_device_pointer
// throws CudaError.
#include <cstddef>
#include <cstdint>

namespace cg::device_memory {

// `bytes` of device memory on the current device (CudaError on failure; ResourceError when the device
// is out of memory, saying how much was asked for). release(nullptr) does nothing.
void* allocate(std::size_t bytes);
void release(void* p) noexcept;

// Synchronous copies (the legacy default stream): host → device, device → host.
void copy_to_device(void* device_dst, const void* host_src, std::size_t bytes);
void copy_to_host(void* host_dst, const void* device_src, std::size_t bytes);

// Waits for the work queued on a stream as __cuda_array_interface__ v3 names it: 1 the legacy default
// stream, 2 the per-thread default stream, any other value a cudaStream_t (0 is not a valid handle there).
void synchronize_stream(std::uintptr_t stream);

// True when `p` is memory the current device's kernels read (device or managed memory); false for
// host memory, and always false in builds without CUDA.
bool is_device_pointer(const void* p);

// The CUDA device whose memory `p` is (the current device for null or host memory): what a DLPack
// consumer is told the memory lives on. CudaError in builds without CUDA.
int device_of(const void* p);

}  // namespace cg::device_memory
