// Seam, CUDA build: device discovery through the CUDA runtime and the 3x3-block SpMV through
// cuSPARSE (cusparse<t>bsrmv, row-major blocks). One handle per process, created on first use.
#include <cuda_runtime.h>
#include <cusparse.h>

#include <mutex>
#include <string>

#include "seam.hpp"

namespace loom::cuda {

int seam_device_count(std::string& error) {
  int count = 0;
  const cudaError_t e = cudaGetDeviceCount(&count);
  if (e != cudaSuccess) {
    error = std::string("cudaGetDeviceCount failed: ") + cudaGetErrorString(e);
    return 0;
  }
  if (count == 0) error = "cudaGetDeviceCount found no CUDA device";
  return count;
}

void seam_require_device(const std::string& scene_source) {
  std::string why;
  if (seam_device_count(why) > 0) return;
  throw InputError((scene_source.empty() ? std::string() : scene_source + ": ") +
                   "backend: cuda needs a usable NVIDIA GPU, but " + why +
                   " (no GPU, or no driver). Fix: set backend: cpu (the same scene runs on the CPU backend).");
}

bool seam_device_memory(std::size_t& free_bytes, std::size_t& total_bytes, std::string& error) {
  std::size_t f = 0, t = 0;
  const cudaError_t e = cudaMemGetInfo(&f, &t);
  if (e != cudaSuccess) {
    error = std::string("cudaMemGetInfo failed: ") + cudaGetErrorString(e);
    return false;
  }
  free_bytes = f;
  total_bytes = t;
  error.clear();
  return true;
}

namespace {
struct Sparse {
  cusparseHandle_t handle = nullptr;
  cusparseMatDescr_t descr = nullptr;
};
Sparse& sparse() {
  static Sparse s;
  static std::once_flag once;
  std::call_once(once, [] {
    if (cusparseCreate(&s.handle) != CUSPARSE_STATUS_SUCCESS) throw SolverError("cusparse: cusparseCreate failed");
    cusparseCreateMatDescr(&s.descr);
    cusparseSetMatType(s.descr, CUSPARSE_MATRIX_TYPE_GENERAL);
    cusparseSetMatIndexBase(s.descr, CUSPARSE_INDEX_BASE_ZERO);
  });
  return s;
}
void check(cusparseStatus_t st) {
  if (st != CUSPARSE_STATUS_SUCCESS)
    throw SolverError(std::string("cusparse bsrmv failed: ") + cusparseGetErrorString(st));
}
}  // namespace

void seam_bsr_spmv(Index nb, Index nnzb, const Index* rp, const Index* col, const double* val, const double* x,
                   double* y) {
  const double one = 1.0, zero = 0.0;
  Sparse& s = sparse();
  check(cusparseDbsrmv(s.handle, CUSPARSE_DIRECTION_ROW, CUSPARSE_OPERATION_NON_TRANSPOSE, nb, nb, nnzb, &one,
                       s.descr, val, rp, col, 3, x, &zero, y));
}

void seam_bsr_spmv(Index nb, Index nnzb, const Index* rp, const Index* col, const float* val, const float* x,
                   float* y) {
  const float one = 1.0f, zero = 0.0f;
  Sparse& s = sparse();
  check(cusparseSbsrmv(s.handle, CUSPARSE_DIRECTION_ROW, CUSPARSE_OPERATION_NON_TRANSPOSE, nb, nb, nnzb, &one,
                       s.descr, val, rp, col, 3, x, &zero, y));
}

void seam_synchronize() { cudaDeviceSynchronize(); }

}  // namespace loom::cuda
