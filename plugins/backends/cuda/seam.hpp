// The seam of the CUDA backend: the few calls that differ between the real CUDA build
// (CUDA runtime + cuSPARSE, seam_cuda.cu) and the Thrust-OpenMP test build (seam_omp.cpp,
// where a Thrust SpMV stands in). Everything else in plugins/backends/cuda is Thrust glue
// over the shared LOOM_HD kernels and compiles unchanged for both device systems.
#pragma once

#include <cstddef>
#include <string>

#include "loom/common.hpp"

namespace loom::cuda {

/// Number of usable devices; on failure 0 with the reason in `error`. The OpenMP build
/// always has one (the host).
int seam_device_count(std::string& error);

/// Throws InputError naming what is missing when there is no usable device.
void seam_require_device(const std::string& scene_source);

/// y = A x for a 3x3-block BSR matrix (row-major blocks, zero-based, sorted columns) with nb
/// block rows and nnzb blocks. All pointers are device pointers; x and y must not alias.
void seam_bsr_spmv(Index nb, Index nnzb, const Index* row_ptr, const Index* col, const double* values,
                   const double* x, double* y);
void seam_bsr_spmv(Index nb, Index nnzb, const Index* row_ptr, const Index* col, const float* values,
                   const float* x, float* y);

/// Free and total device memory in bytes (cudaMemGetInfo; the OpenMP build reports the host's
/// available and total physical memory). Returns false with the reason when it cannot tell.
bool seam_device_memory(std::size_t& free_bytes, std::size_t& total_bytes, std::string& error);

/// Wait for the device (timings).
void seam_synchronize();

}  // namespace loom::cuda
