#pragma once
// Host/device annotation for the math shared by the CPU backend, the CUDA kernels and the tests.
// CG_HD_OUTLINE: a rare path kept out of line on the device (its registers and stack are not the
// calling kernel's common path's; e.g. fp32's fp64 solves, core/shape_narrow.hpp); still an inline
// definition for the linker, since more than one CUDA translation unit includes the core headers.
#if defined(__CUDACC__)
#define CG_HD __host__ __device__ __forceinline__
#define CG_HD_OUTLINE __host__ __device__ __noinline__ inline
#else
#define CG_HD inline
#define CG_HD_OUTLINE inline
#endif
