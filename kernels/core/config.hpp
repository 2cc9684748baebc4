#pragma once
// Host/device annotation for the math shared by the CPU backend, the CUDA kernels and the tests.
#if defined(__CUDACC__)
#define CG_HD __host__ __device__ __forceinline__
#else
#define CG_HD inline
#endif
