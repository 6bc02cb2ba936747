// The 3x3-block row product y_i = sum_k A_ik x_col(k), shared by the filtered PCG's SpMV
// (eigen_pcg.cpp) and the smoothed-aggregation smoother and residual (sa_amg.cpp).
#pragma once

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

#include <cstddef>

#include "loom/common.hpp"
#include "loom/kernels/bsr_ops.hpp"

namespace loom {

// y_i = sum_k A_ik x_col(k) over block row i. The AVX2 path keeps one 4-lane accumulator
// per block row (lane 3 multiplies a zero) and reduces once per vertex instead of once per
// block; the scalar path is the shared kernel.
inline void block_row_multiply3(const Index* rp, const Index* col, const double* val, const double* x, Index i,
                         double* yi) {
#if defined(__AVX2__) && defined(__FMA__)
  const __m256i m3 = _mm256_setr_epi64x(-1, -1, -1, 0);
  __m256d a0 = _mm256_setzero_pd(), a1 = _mm256_setzero_pd(), a2 = _mm256_setzero_pd();
  for (Index k = rp[i]; k < rp[i + 1]; ++k) {
    const double* B = val + 9 * static_cast<std::size_t>(k);
    const __m256d xv = _mm256_maskload_pd(x + 3 * static_cast<std::size_t>(col[k]), m3);
    a0 = _mm256_fmadd_pd(_mm256_loadu_pd(B), xv, a0);
    a1 = _mm256_fmadd_pd(_mm256_loadu_pd(B + 3), xv, a1);
    a2 = _mm256_fmadd_pd(_mm256_maskload_pd(B + 6, m3), xv, a2);
  }
  const __m256d h01 = _mm256_hadd_pd(a0, a1);  // [a0_0+a0_1, a1_0+a1_1, a0_2+a0_3, a1_2+a1_3]
  const __m128d s01 = _mm_add_pd(_mm256_castpd256_pd128(h01), _mm256_extractf128_pd(h01, 1));
  const __m128d l2 = _mm_add_pd(_mm256_castpd256_pd128(a2), _mm256_extractf128_pd(a2, 1));
  yi[0] = _mm_cvtsd_f64(s01);
  yi[1] = _mm_cvtsd_f64(_mm_unpackhi_pd(s01, s01));
  yi[2] = _mm_cvtsd_f64(_mm_add_sd(l2, _mm_unpackhi_pd(l2, l2)));
#else
  kernels::bsr_row_multiply(rp, col, val, x, i, yi);
#endif
}

}  // namespace loom
