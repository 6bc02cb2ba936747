// The filtered PCG's SpMV from a float copy of A (PcgOptions::float_spmv, `spmv_storage: float`):
// the 3x3 blocks are stored as 9 floats (36 bytes instead of 72) and widened to double in the
// product, so the SpMV reads about half the bytes (the column indices stay) while the vector
// and every sum stay double. The copy A_f = fl32(A) is exactly symmetric when A is (rounding is
// elementwise), so the iteration is CG on A_f; the start and the stopping rule use the double A
// (filtered_pcg.hpp restarts from the true residual when the two drift apart), so the answer
// still meets the tolerance on A. Each product entry differs from the double one by at most
// 2^-24 sum_j |A_ij| |c_j| plus double rounding (tests/sa_amg/test_float_spmv.cpp).
#pragma once

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

#include <cstddef>
#include <vector>

#include "loom/common.hpp"
#include "loom/kernels/bsr_ops.hpp"

namespace loom {

/// af = float(values) (9 per block) followed by 4 zeros: the AVX2 row product loads 4 floats
/// from the last row of a block, the 4th (the next block's first entry, or the padding) times
/// a zero lane of x; it must be finite, hence the zeros rather than uninitialised padding.
/// Resizes (allocates) only when the block count changes.
inline void float_copy_values(const std::vector<double>& values, std::vector<float>& af, bool parallel) {
  const std::size_t m = values.size();
  if (af.size() != m + 4) af.assign(m + 4, 0.0f);
  const long long mm = static_cast<long long>(m);
  float* out = af.data();
  const double* in = values.data();
#pragma omp parallel for schedule(static) if (parallel)
  for (long long k = 0; k < mm; ++k) out[k] = static_cast<float>(in[k]);
}

/// y_i = sum_k A_f,ik x_col(k) over block row i, A_f's blocks as 9 floats (float_copy_values),
/// x and y double.
inline void block_row_multiply3f(const Index* rp, const Index* col, const float* val, const double* x, Index i,
                                 double* yi) {
#if defined(__AVX2__) && defined(__FMA__)
  const __m256i m3 = _mm256_setr_epi64x(-1, -1, -1, 0);
  __m256d a0 = _mm256_setzero_pd(), a1 = _mm256_setzero_pd(), a2 = _mm256_setzero_pd();
  for (Index k = rp[i]; k < rp[i + 1]; ++k) {
    const float* B = val + 9 * static_cast<std::size_t>(k);
    const __m256d xv = _mm256_maskload_pd(x + 3 * static_cast<std::size_t>(col[k]), m3);
    a0 = _mm256_fmadd_pd(_mm256_cvtps_pd(_mm_loadu_ps(B)), xv, a0);
    a1 = _mm256_fmadd_pd(_mm256_cvtps_pd(_mm_loadu_ps(B + 3)), xv, a1);
    a2 = _mm256_fmadd_pd(_mm256_cvtps_pd(_mm_loadu_ps(B + 6)), xv, a2);
  }
  const __m256d h01 = _mm256_hadd_pd(a0, a1);
  const __m128d s01 = _mm_add_pd(_mm256_castpd256_pd128(h01), _mm256_extractf128_pd(h01, 1));
  const __m128d l2 = _mm_add_pd(_mm256_castpd256_pd128(a2), _mm256_extractf128_pd(a2, 1));
  yi[0] = _mm_cvtsd_f64(s01);
  yi[1] = _mm_cvtsd_f64(_mm_unpackhi_pd(s01, s01));
  yi[2] = _mm_cvtsd_f64(_mm_add_sd(l2, _mm_unpackhi_pd(l2, l2)));
#else
  double y0 = 0, y1 = 0, y2 = 0;
  for (Index k = rp[i]; k < rp[i + 1]; ++k) {
    const float* B = val + 9 * static_cast<std::size_t>(k);
    const double* xj = x + 3 * static_cast<std::size_t>(col[k]);
    y0 += double(B[0]) * xj[0] + double(B[1]) * xj[1] + double(B[2]) * xj[2];
    y1 += double(B[3]) * xj[0] + double(B[4]) * xj[1] + double(B[5]) * xj[2];
    y2 += double(B[6]) * xj[0] + double(B[7]) * xj[1] + double(B[8]) * xj[2];
  }
  yi[0] = y0;
  yi[1] = y1;
  yi[2] = y2;
#endif
}

}  // namespace loom
