// The block-row products y_i = sum_k A_ik x_col(k) over 3x3 and 6x6 blocks, one template for
// blocks stored in double or in float (widened to double on load; x, y and every sum stay
// double). Shared by the filtered PCG's SpMV (eigen_pcg.cpp, double A or its float copy,
// float_spmv.hpp), the SpMV from the upper triangle (upper_spmv.hpp) and the
// smoothed-aggregation smoother and residual (sa_amg.cpp, every level, either storage).
#pragma once

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "loom/common.hpp"
#include "loom/kernels/bsr_ops.hpp"
#include "half.hpp"

namespace loom {

#if defined(__AVX2__) && defined(__FMA__)
namespace block_row_detail {

// 4 entries from p as doubles.
template <class T>
inline __m256d load4(const T* p) {
  if constexpr (std::is_same_v<T, Half>) {
#if defined(__F16C__)
    return _mm256_cvtps_pd(_mm_cvtph_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p))));
#else
    return _mm256_setr_pd(widen(p[0]), widen(p[1]), widen(p[2]), widen(p[3]));
#endif
  }
  else if constexpr (std::is_same_v<T, float>)
    return _mm256_cvtps_pd(_mm_loadu_ps(p));
  else
    return _mm256_loadu_pd(p);
}
// 3 entries from p as doubles, lane 3 zero (reads nothing past p[2]).
template <class T>
inline __m256d load3(const T* p) {
  if constexpr (std::is_same_v<T, float>)
    return _mm256_cvtps_pd(_mm_maskload_ps(p, _mm_setr_epi32(-1, -1, -1, 0)));
  else
    return _mm256_maskload_pd(p, _mm256_setr_epi64x(-1, -1, -1, 0));
}
// 2 entries from p as doubles.
template <class T>
inline __m128d load2(const T* p) {
  if constexpr (std::is_same_v<T, Half>) {
#if defined(__F16C__)
    std::int32_t two;
    std::memcpy(&two, p, 4);
    return _mm_cvtps_pd(_mm_cvtph_ps(_mm_cvtsi32_si128(two)));
#else
    return _mm_setr_pd(widen(p[0]), widen(p[1]));
#endif
  } else if constexpr (std::is_same_v<T, float>)
    return _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p))));
  else
    return _mm_loadu_pd(p);
}

// The 5 accumulators of the 18-value block kernels (4 runs of 4 lanes, one of 2) into t[0..17],
// in block order, for the per-row reduction.
inline void store_runs18(double* t, __m256d a0, __m256d a1, __m256d a2, __m256d a3, __m128d a4) {
  _mm256_store_pd(t, a0);
  _mm256_store_pd(t + 4, a1);
  _mm256_store_pd(t + 8, a2);
  _mm256_store_pd(t + 12, a3);
  _mm_store_pd(t + 16, a4);
}

}  // namespace block_row_detail
#endif

// y_i = sum_k A_ik x_col(k) over block row i of a 3x3-block matrix (9 values of T per block).
// The AVX2 path keeps one 4-lane accumulator per block row and reduces once per vertex
// instead of once per block; the first two rows of a block are read 4 wide, their 4th lane
// (the next entry of the block, finite) multiplying x's masked zero, the last row by a masked
// load, so nothing is read past the last block. The scalar double path is the shared kernel.
template <class T>
inline void block_row_multiply3(const Index* rp, const Index* col, const T* val, const double* x, Index i,
                                double* yi) {
  static_assert(std::is_same_v<T, double> || std::is_same_v<T, float>);
#if defined(__AVX2__) && defined(__FMA__)
  using namespace block_row_detail;
  const __m256i m3 = _mm256_setr_epi64x(-1, -1, -1, 0);
  __m256d a0 = _mm256_setzero_pd(), a1 = _mm256_setzero_pd(), a2 = _mm256_setzero_pd();
  for (Index k = rp[i]; k < rp[i + 1]; ++k) {
    const T* B = val + 9 * static_cast<std::size_t>(k);
    const __m256d xv = _mm256_maskload_pd(x + 3 * static_cast<std::size_t>(col[k]), m3);
    a0 = _mm256_fmadd_pd(load4(B), xv, a0);
    a1 = _mm256_fmadd_pd(load4(B + 3), xv, a1);
    a2 = _mm256_fmadd_pd(load3(B + 6), xv, a2);
  }
  const __m256d h01 = _mm256_hadd_pd(a0, a1);  // [a0_0+a0_1, a1_0+a1_1, a0_2+a0_3, a1_2+a1_3]
  const __m128d s01 = _mm_add_pd(_mm256_castpd256_pd128(h01), _mm256_extractf128_pd(h01, 1));
  const __m128d l2 = _mm_add_pd(_mm256_castpd256_pd128(a2), _mm256_extractf128_pd(a2, 1));
  yi[0] = _mm_cvtsd_f64(s01);
  yi[1] = _mm_cvtsd_f64(_mm_unpackhi_pd(s01, s01));
  yi[2] = _mm_cvtsd_f64(_mm_add_sd(l2, _mm_unpackhi_pd(l2, l2)));
#else
  if constexpr (std::is_same_v<T, double>) {
    kernels::bsr_row_multiply(rp, col, val, x, i, yi);
  } else {
    double y0 = 0, y1 = 0, y2 = 0;
    for (Index k = rp[i]; k < rp[i + 1]; ++k) {
      const T* B = val + 9 * static_cast<std::size_t>(k);
      const double* xj = x + 3 * static_cast<std::size_t>(col[k]);
      y0 += double(B[0]) * xj[0] + double(B[1]) * xj[1] + double(B[2]) * xj[2];
      y1 += double(B[3]) * xj[0] + double(B[4]) * xj[1] + double(B[5]) * xj[2];
      y2 += double(B[6]) * xj[0] + double(B[7]) * xj[1] + double(B[8]) * xj[2];
    }
    yi[0] = y0;
    yi[1] = y1;
    yi[2] = y2;
  }
#endif
}

// y_i = sum_k A_ik x_col(k) over block row i of a 6x6-block matrix (36 values of T per
// block). The AVX2 path reads a block as 9 runs of 4 consecutive values (rows 2r and 2r+1
// span runs 3r..3r+2), each multiplied by the matching 4 entries of x: (x0..x3), (x4, x5,
// x0, x1), (x2..x5), into 9 accumulators reduced once per block row: 9 loads and 9 FMAs per
// block instead of 12 of each with 4- and 2-lane halves per row.
template <class T>
inline void block_row_multiply6(const Index* rp, const Index* col, const T* val, const double* x, Index i,
                                double* yi) {
  static_assert(std::is_same_v<T, double> || std::is_same_v<T, float>);
#if defined(__AVX2__) && defined(__FMA__)
  using namespace block_row_detail;
  __m256d acc[9];
  for (int r = 0; r < 9; ++r) acc[r] = _mm256_setzero_pd();
  for (Index k = rp[i]; k < rp[i + 1]; ++k) {
    const T* B = val + 36 * static_cast<std::size_t>(k);
    const double* xk = x + 6 * static_cast<std::size_t>(col[k]);
    const __m256d x0 = _mm256_loadu_pd(xk);                // x0 x1 x2 x3
    const __m256d x2 = _mm256_loadu_pd(xk + 2);            // x2 x3 x4 x5
    const __m256d x1 = _mm256_permute2f128_pd(x2, x0, 0x21);  // x4 x5 x0 x1
    for (int q = 0; q < 3; ++q) {
      acc[3 * q] = _mm256_fmadd_pd(load4(B + 12 * q), x0, acc[3 * q]);
      acc[3 * q + 1] = _mm256_fmadd_pd(load4(B + 12 * q + 4), x1, acc[3 * q + 1]);
      acc[3 * q + 2] = _mm256_fmadd_pd(load4(B + 12 * q + 8), x2, acc[3 * q + 2]);
    }
  }
  for (int q = 0; q < 3; ++q) {
    // row 2q: all of run 3q + the low half of run 3q+1; row 2q+1: its high half + run 3q+2.
    const __m128d a_lo = _mm256_castpd256_pd128(acc[3 * q]), a_hi = _mm256_extractf128_pd(acc[3 * q], 1);
    const __m128d m_lo = _mm256_castpd256_pd128(acc[3 * q + 1]), m_hi = _mm256_extractf128_pd(acc[3 * q + 1], 1);
    const __m128d c_lo = _mm256_castpd256_pd128(acc[3 * q + 2]), c_hi = _mm256_extractf128_pd(acc[3 * q + 2], 1);
    const __m128d r0 = _mm_add_pd(_mm_add_pd(a_lo, a_hi), m_lo);
    const __m128d r1 = _mm_add_pd(_mm_add_pd(c_lo, c_hi), m_hi);
    const __m128d h = _mm_hadd_pd(r0, r1);
    yi[2 * q] = _mm_cvtsd_f64(h);
    yi[2 * q + 1] = _mm_cvtsd_f64(_mm_unpackhi_pd(h, h));
  }
#else
  for (int r = 0; r < 6; ++r) yi[r] = 0;
  for (Index k = rp[i]; k < rp[i + 1]; ++k) {
    const T* B = val + 36 * static_cast<std::size_t>(k);
    const double* xk = x + 6 * static_cast<std::size_t>(col[k]);
    for (int r = 0; r < 6; ++r) {
      double s = 0;
      for (int q = 0; q < 6; ++q) s += double(B[6 * r + q]) * xk[q];
      yi[r] += s;
    }
  }
#endif
}

// The level-0 transfers of the rigid-body hierarchy (3x6 blocks of P, 6x3 blocks of R = Pᵀ,
// both row-major, 18 values of T per block). The AVX2 paths read a block as 4 runs of 4
// values and one of 2, each multiplied by the matching entries of the vector (the run pattern
// repeats every 3 entries for R and every 6 for P), into 5 accumulators reduced once per block
// row, as block_row_multiply6 does: 5 loads and 5 FMAs per block instead of 18 scalar
// products in 3- or 6-term dot products. The sums are the same products added in another
// order (rounding-level differences from the scalar loops). Their values may also be IEEE
// half (half.hpp, sa_amg's `half_transfers`), widened to double on load like float.

// y_I = sum_k R_Ik r_col(k) over block row I of R (6x3 blocks): the restriction b_c = R r.
template <class T>
inline void block_row_restrict63(const Index* rp, const Index* col, const T* val, const double* r, Index I,
                                 double* yI) {
  static_assert(std::is_same_v<T, double> || std::is_same_v<T, float> || std::is_same_v<T, Half>);
#if defined(__AVX2__) && defined(__FMA__)
  using namespace block_row_detail;
  const __m256i m3 = _mm256_setr_epi64x(-1, -1, -1, 0);
  __m256d a0 = _mm256_setzero_pd(), a1 = _mm256_setzero_pd(), a2 = _mm256_setzero_pd(), a3 = _mm256_setzero_pd();
  __m128d a4 = _mm_setzero_pd();
  for (Index k = rp[I]; k < rp[I + 1]; ++k) {
    const T* B = val + 18 * static_cast<std::size_t>(k);
    const __m256d v = _mm256_maskload_pd(r + 3 * static_cast<std::size_t>(col[k]), m3);  // r0 r1 r2 0
    const __m256d p0 = _mm256_permute4x64_pd(v, 0x24);  // r0 r1 r2 r0
    const __m256d p1 = _mm256_permute4x64_pd(v, 0x49);  // r1 r2 r0 r1
    const __m256d p2 = _mm256_permute4x64_pd(v, 0x92);  // r2 r0 r1 r2
    a0 = _mm256_fmadd_pd(load4(B), p0, a0);
    a1 = _mm256_fmadd_pd(load4(B + 4), p1, a1);
    a2 = _mm256_fmadd_pd(load4(B + 8), p2, a2);
    a3 = _mm256_fmadd_pd(load4(B + 12), p0, a3);
    a4 = _mm_fmadd_pd(load2(B + 16), _mm256_castpd256_pd128(p1), a4);
  }
  alignas(32) double t[20];
  store_runs18(t, a0, a1, a2, a3, a4);
  for (int c = 0; c < 6; ++c) yI[c] = t[3 * c] + t[3 * c + 1] + t[3 * c + 2];
#else
  for (int c = 0; c < 6; ++c) yI[c] = 0;
  for (Index k = rp[I]; k < rp[I + 1]; ++k) {
    const T* B = val + 18 * static_cast<std::size_t>(k);
    const double* rk = r + 3 * static_cast<std::size_t>(col[k]);
    for (int c = 0; c < 6; ++c)
      yI[c] += widen(B[3 * c]) * rk[0] + widen(B[3 * c + 1]) * rk[1] + widen(B[3 * c + 2]) * rk[2];
  }
#endif
}

// x_i += sum_k P_ik xc_col(k) over block row i of P (3x6 blocks): the prolongation x += P x_c.
template <class T>
inline void block_row_prolong36_add(const Index* rp, const Index* col, const T* val, const double* xc, Index i,
                                    double* xi) {
  static_assert(std::is_same_v<T, double> || std::is_same_v<T, float> || std::is_same_v<T, Half>);
#if defined(__AVX2__) && defined(__FMA__)
  using namespace block_row_detail;
  __m256d a0 = _mm256_setzero_pd(), a1 = _mm256_setzero_pd(), a2 = _mm256_setzero_pd(), a3 = _mm256_setzero_pd();
  __m128d a4 = _mm_setzero_pd();
  for (Index k = rp[i]; k < rp[i + 1]; ++k) {
    const T* B = val + 18 * static_cast<std::size_t>(k);
    const double* xk = xc + 6 * static_cast<std::size_t>(col[k]);
    const __m256d x0 = _mm256_loadu_pd(xk);                   // x0 x1 x2 x3
    const __m256d x2 = _mm256_loadu_pd(xk + 2);               // x2 x3 x4 x5
    const __m256d x1 = _mm256_permute2f128_pd(x2, x0, 0x21);  // x4 x5 x0 x1
    a0 = _mm256_fmadd_pd(load4(B), x0, a0);                   // row 0, columns 0-3
    a1 = _mm256_fmadd_pd(load4(B + 4), x1, a1);               // row 0 columns 4-5, row 1 columns 0-1
    a2 = _mm256_fmadd_pd(load4(B + 8), x2, a2);               // row 1, columns 2-5
    a3 = _mm256_fmadd_pd(load4(B + 12), x0, a3);              // row 2, columns 0-3
    a4 = _mm_fmadd_pd(load2(B + 16), _mm256_castpd256_pd128(x1), a4);  // row 2, columns 4-5
  }
  alignas(32) double t[20];
  store_runs18(t, a0, a1, a2, a3, a4);
  xi[0] += (t[0] + t[1]) + (t[2] + t[3]) + (t[4] + t[5]);
  xi[1] += (t[6] + t[7]) + (t[8] + t[9]) + (t[10] + t[11]);
  xi[2] += (t[12] + t[13]) + (t[14] + t[15]) + (t[16] + t[17]);
#else
  for (Index k = rp[i]; k < rp[i + 1]; ++k) {
    const T* B = val + 18 * static_cast<std::size_t>(k);
    const double* xk = xc + 6 * static_cast<std::size_t>(col[k]);
    for (int a = 0; a < 3; ++a) {
      double s = 0;
      for (int c = 0; c < 6; ++c) s += widen(B[6 * a + c]) * xk[c];
      xi[a] += s;
    }
  }
#endif
}

}  // namespace loom
