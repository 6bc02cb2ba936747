// Seam, Thrust-OpenMP build: the host stands in for the device, a Thrust SpMV stands in
// for cuSPARSE (same block-row math as the CPU backend: kernels::bsr_row_multiply).
#include <unistd.h>

#include <thrust/execution_policy.h>
#include <thrust/for_each.h>
#include <thrust/iterator/counting_iterator.h>

#include "loom/kernels/bsr_ops.hpp"
#include "seam.hpp"

namespace loom::cuda {

int seam_device_count(std::string& error) {
  error.clear();
  return 1;
}

void seam_require_device(const std::string&) {}

bool seam_device_memory(std::size_t& free_bytes, std::size_t& total_bytes, std::string& error) {
  const long page = sysconf(_SC_PAGESIZE), avail = sysconf(_SC_AVPHYS_PAGES), phys = sysconf(_SC_PHYS_PAGES);
  if (page <= 0 || avail < 0 || phys <= 0) {
    error = "sysconf cannot tell the physical memory";
    return false;
  }
  free_bytes = static_cast<std::size_t>(avail) * static_cast<std::size_t>(page);
  total_bytes = static_cast<std::size_t>(phys) * static_cast<std::size_t>(page);
  error.clear();
  return true;
}

namespace {
template <class T>
void spmv(Index nb, const Index* rp, const Index* col, const T* val, const T* x, T* y) {
  thrust::for_each(thrust::device, thrust::counting_iterator<Index>(0), thrust::counting_iterator<Index>(nb),
                   kernels::BsrRowProduct<T, Index>{rp, col, val, x, y});
}
}  // namespace

void seam_bsr_spmv(Index nb, Index, const Index* rp, const Index* col, const double* val, const double* x,
                   double* y) {
  spmv(nb, rp, col, val, x, y);
}
void seam_bsr_spmv(Index nb, Index, const Index* rp, const Index* col, const float* val, const float* x, float* y) {
  spmv(nb, rp, col, val, x, y);
}

void seam_synchronize() {}

}  // namespace loom::cuda
