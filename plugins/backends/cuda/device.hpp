// Thrust glue of the CUDA backend: device vectors, a parallel-for over indices, reductions and
// host <-> device copies with precision conversion. Compiles for THRUST_DEVICE_SYSTEM CUDA
// (nvcc, the loom_backend_cuda module) and OMP (g++ -fopenmp, tests/cuda).
// Functors passed to parallel_for are plain structs with a LOOM_HD operator()(Index).
#pragma once

#include <thrust/copy.h>
#include <thrust/device_vector.h>
#include <thrust/execution_policy.h>
#include <thrust/fill.h>
#include <thrust/for_each.h>
#include <thrust/functional.h>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/transform_reduce.h>

#include <algorithm>
#include <new>
#include <string>
#include <vector>

#include "loom/common.hpp"
#include "seam.hpp"

#if THRUST_DEVICE_SYSTEM == THRUST_DEVICE_SYSTEM_CUDA
#include <cuda_runtime.h>
#include <thrust/system/cuda/execution_policy.h>
#endif

namespace loom::cuda {

#if THRUST_DEVICE_SYSTEM == THRUST_DEVICE_SYSTEM_CUDA
/// Temporary storage of Thrust's reductions, kept between calls (one block that only grows), so
/// that the step loop does no cudaMalloc/cudaFree per reduction. One reduction at a time
/// (the backend runs on one host thread); the block lives until the process ends.
class ScratchAllocator {
 public:
  using value_type = char;
  char* allocate(std::ptrdiff_t n) {
    if (n > size_) {
      if (ptr_) cudaFree(ptr_);
      ptr_ = nullptr;
      size_ = 0;
      if (cudaMalloc(reinterpret_cast<void**>(&ptr_), static_cast<std::size_t>(n)) != cudaSuccess)
        throw SolverError("backend cuda: cudaMalloc of " + std::to_string(n) + " bytes of reduction scratch failed");
      size_ = n;
    }
    return ptr_;
  }
  void deallocate(char*, std::size_t) {}

 private:
  char* ptr_ = nullptr;
  std::ptrdiff_t size_ = 0;
};
inline ScratchAllocator& scratch() {
  static ScratchAllocator a;
  return a;
}
#define LOOM_CUDA_REDUCE_POLICY thrust::cuda::par(::loom::cuda::scratch())
#else
#define LOOM_CUDA_REDUCE_POLICY thrust::device
#endif

template <class T>
using DVec = thrust::device_vector<T>;

template <class T>
T* raw(DVec<T>& v) {
  return thrust::raw_pointer_cast(v.data());
}
template <class T>
const T* raw(const DVec<T>& v) {
  return thrust::raw_pointer_cast(v.data());
}

#if THRUST_DEVICE_SYSTEM == THRUST_DEVICE_SYSTEM_OMP
/// OpenMP stand-in only: launches over fewer items than this run on the calling thread (an
/// OpenMP region costs more than such a loop, and far more on an oversubscribed machine).
/// Tests set it to 0 to exercise the parallel path.
inline Index& omp_serial_below() {
  static Index v = 4096;
  return v;
}
#define LOOM_CUDA_OMP_STANDIN 1
#endif

/// f(i) for i in [begin, end) on the device.
template <class F>
void parallel_for(Index begin, Index end, const F& f) {
  if (end <= begin) return;
#ifdef LOOM_CUDA_OMP_STANDIN
  if (end - begin < omp_serial_below()) {
    thrust::for_each(thrust::seq, thrust::counting_iterator<Index>(begin), thrust::counting_iterator<Index>(end), f);
    return;
  }
#endif
  thrust::for_each(thrust::device, thrust::counting_iterator<Index>(begin), thrust::counting_iterator<Index>(end), f);
}
template <class F>
void parallel_for(Index n, const F& f) {
  parallel_for(Index(0), n, f);
}

/// sum_i f(i) over [0, n) on the device (f returns T).
template <class T, class F>
T reduce_sum(Index n, const F& f) {
  if (n <= 0) return T(0);
#ifdef LOOM_CUDA_OMP_STANDIN
  // An OpenMP reduction of our own: Thrust's OpenMP reduce assigns its partial sums through a
  // thrust::reference built on a null system pointer (UBSan: reference bound to null).
  T sum = T(0);
  if (n < omp_serial_below()) {
    for (Index i = 0; i < n; ++i) sum += f(i);
    return sum;
  }
#pragma omp parallel for reduction(+ : sum) schedule(static)
  for (Index i = 0; i < n; ++i) sum += f(i);
  return sum;
#else
  return thrust::transform_reduce(LOOM_CUDA_REDUCE_POLICY, thrust::counting_iterator<Index>(0),
                                  thrust::counting_iterator<Index>(n), f, T(0), thrust::plus<T>());
#endif
}

/// min_i f(i) over [0, n) on the device (f returns an Index); `none` when n <= 0.
template <class F>
Index reduce_min_index(Index n, const F& f, Index none) {
  if (n <= 0) return none;
#ifdef LOOM_CUDA_OMP_STANDIN
  Index m = none;  // an OpenMP reduction of our own, as in reduce_sum
  if (n < omp_serial_below()) {
    for (Index i = 0; i < n; ++i) m = std::min(m, f(i));
    return m;
  }
#pragma omp parallel for reduction(min : m) schedule(static)
  for (Index i = 0; i < n; ++i) m = std::min(m, f(i));
  return m;
#else
  return thrust::transform_reduce(LOOM_CUDA_REDUCE_POLICY, thrust::counting_iterator<Index>(0),
                                  thrust::counting_iterator<Index>(n), f, none, thrust::minimum<Index>());
#endif
}

/// One term a[i] * b[i] of a dot product, over raw pointers.
template <class T>
struct DotTerm {
  const T* a;
  const T* b;
  LOOM_HD T operator()(Index i) const { return a[i] * b[i]; }
};

/// out[i] = in[i] converted to another scalar (the mixed-precision solve's float <-> double copies).
template <class From, class To>
struct ConvertKernel {
  const From* in;
  To* out;
  LOOM_HD void operator()(Index i) const { out[i] = static_cast<To>(in[i]); }
};

/// a . b over the whole vectors (0 for empty vectors). It reduces over raw pointers: Thrust's
/// inner_product on device iterators converts device references through a null system pointer
/// on the OpenMP system, and an empty vector's begin() is null (UBSan reports both as a
/// reference bound to null).
template <class T>
T dot(const DVec<T>& a, const DVec<T>& b) {
  const Index n = static_cast<Index>(a.size() < b.size() ? a.size() : b.size());
  if (n == 0) return T(0);
  return reduce_sum<T>(n, DotTerm<T>{raw(a), raw(b)});
}

/// Tests only: caps the device memory the backend believes is free (0 = no cap), to exercise
/// the out-of-memory path without filling a device.
inline std::size_t& device_memory_cap() {
  static std::size_t cap = 0;
  return cap;
}

inline std::string mib(std::size_t bytes) {
  return std::to_string((bytes + (std::size_t(1) << 20) - 1) >> 20) + " MiB";
}

/// Before a device integrator allocates: throws InputError naming the need, what is free and
/// the fix when `bytes` (the integrator's estimate of its device arrays) exceed the free device
/// memory (or the test cap).
inline void require_device_memory(std::size_t bytes, const std::string& scene_source, const std::string& what) {
  std::size_t free_bytes = 0, total = 0;
  std::string why;
  if (!seam_device_memory(free_bytes, total, why)) return;  // cannot tell: the allocation itself decides
  if (device_memory_cap() > 0 && device_memory_cap() < free_bytes) free_bytes = device_memory_cap();
  if (bytes <= free_bytes) return;
  throw InputError((scene_source.empty() ? std::string() : scene_source + ": ") + "backend cuda: " + what +
                   " needs about " + mib(bytes) + " of device memory, but only " + mib(free_bytes) + " of " +
                   mib(total) + " are free. Fix: use a coarser mesh, precision: float (half the memory), "
                   "or backend: cpu.");
}

/// v = n copies of T(0), turning an allocation failure (cudaMalloc out of memory; malloc on the
/// OpenMP system) into InputError with the fix instead of an uncaught thrust::system::detail::bad_alloc.
template <class T>
void device_assign(DVec<T>& v, std::size_t n, const std::string& what) {
  try {
    v.assign(n, T(0));
  } catch (const std::bad_alloc&) {
    std::size_t free_bytes = 0, total = 0;
    std::string why;
    const bool known = seam_device_memory(free_bytes, total, why);
    throw InputError("backend cuda: allocating " + what + " (" + mib(n * sizeof(T)) + ") failed: out of device memory" +
                     (known ? " (" + mib(free_bytes) + " of " + mib(total) + " free)" : std::string()) +
                     ". Fix: use a coarser mesh, precision: float (half the memory), or backend: cpu.");
  }
}

/// Upload host data (any arithmetic type) into a device vector of T, resizing it.
template <class T, class S>
void upload(const std::vector<S>& host, DVec<T>& dev) {
  if (host.empty()) {  // assign() from an empty host range binds a reference to null
    dev.clear();
    return;
  }
  if constexpr (std::is_same_v<T, S>) {
    dev.assign(host.begin(), host.end());
  } else {
    std::vector<T> tmp(host.begin(), host.end());
    dev.assign(tmp.begin(), tmp.end());
  }
}

/// Download a device vector of T into host doubles (same size), through `stage` for T != double.
template <class T>
void download(const DVec<T>& dev, std::vector<double>& host, std::vector<T>& stage) {
  host.resize(dev.size());
  if (dev.empty()) return;  // copy() from an empty device range binds a reference to null
  if constexpr (std::is_same_v<T, double>) {
    thrust::copy(dev.begin(), dev.end(), host.begin());
  } else {
    stage.resize(dev.size());
    thrust::copy(dev.begin(), dev.end(), stage.begin());
    for (std::size_t k = 0; k < stage.size(); ++k) host[k] = static_cast<double>(stage[k]);
  }
}

template <class T>
void fill(DVec<T>& v, T value) {
  if (v.empty()) return;
  thrust::fill(thrust::device, v.begin(), v.end(), value);
}

}  // namespace loom::cuda
