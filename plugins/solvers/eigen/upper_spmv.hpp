// The filtered PCG's SpMV from the blocks on and above the diagonal only (issue 15): for a
// symmetric 3x3-block matrix, y_i = sum_{j >= i} A_ij x_j + sum_{j < i} A_ji^T x_j, where the
// blocks A_ji (j < i) are read from row j, which the row-parallel loop has streamed a few
// hundred rows earlier (the grid's bandwidth), so they are still in cache. The blocks below
// the diagonal are never read: about 4/7 of the matrix instead of all of it on a
// triangulated grid. Exact for a matrix whose two triangles are transposes of each other,
// so it is used only when the pattern is structurally symmetric and the values agree to
// rounding (`symmetric_values`, checked at every factorize); otherwise the PCG uses the full
// row product.
#pragma once

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

#include "block_row.hpp"
#include "loom/bsr.hpp"
#include "loom/common.hpp"

namespace loom {

class UpperTriangleSpmv {
 public:
  /// Builds the per-row list of the blocks above the diagonal that mirror each row's blocks
  /// below it. False (and the product unusable) when the pattern is not structurally
  /// symmetric or lacks a diagonal block.
  bool analyze(const BsrPattern& P) {
    ok_ = false;
    const Index n = P.n;
    lo_ptr_.assign(static_cast<std::size_t>(n) + 1, 0);
    for (Index j = 0; j < n; ++j) {
      if (P.diag[j] < 0) return false;
      for (Index k = P.diag[j] + 1; k < P.row_ptr[j + 1]; ++k) ++lo_ptr_[P.col[k] + 1];
    }
    for (Index i = 0; i < n; ++i) {
      lo_ptr_[i + 1] += lo_ptr_[i];
      // Row i's blocks below the diagonal must be exactly the mirrors counted above.
      if (lo_ptr_[i + 1] - lo_ptr_[i] != P.diag[i] - P.row_ptr[i]) return false;
    }
    lo_row_.assign(static_cast<std::size_t>(lo_ptr_[n]), 0);
    lo_pos_.assign(lo_row_.size(), 0);
    std::vector<Index> fill(lo_ptr_.begin(), lo_ptr_.end() - 1);
    for (Index j = 0; j < n; ++j)  // increasing j: each row's list comes out sorted
      for (Index k = P.diag[j] + 1; k < P.row_ptr[j + 1]; ++k) {
        const Index i = P.col[k];
        lo_row_[fill[i]] = j;
        lo_pos_[fill[i]++] = k;
      }
    for (Index i = 0; i < n; ++i)
      for (Index t = lo_ptr_[i]; t < lo_ptr_[i + 1]; ++t)
        if (P.col[P.row_ptr[i] + (t - lo_ptr_[i])] != lo_row_[t]) return false;
    ok_ = true;
    return true;
  }
  bool analyzed() const { return ok_; }

  /// max |A_ij - A_ji^T| <= rel * max |A| over the pattern (A's pattern must be the analysed one).
  bool symmetric_values(const BsrMatrix& A, double rel, bool par) const {
    if (!ok_) return false;
    const BsrPattern& P = A.pattern();
    const Index n = P.n;
    double diff = 0, big = 0;
#pragma omp parallel for schedule(static) reduction(max : diff, big) if (par)
    for (Index i = 0; i < n; ++i) {
      for (Index k = P.row_ptr[i]; k < P.row_ptr[i + 1]; ++k) {
        const double* B = A.block(k);
        for (int e = 0; e < 9; ++e) big = std::max(big, std::abs(B[e]));
      }
      for (Index t = lo_ptr_[i]; t < lo_ptr_[i + 1]; ++t) {
        const double* U = A.block(lo_pos_[t]);                              // (j, i), j < i
        const double* L = A.block(P.row_ptr[i] + (t - lo_ptr_[i]));         // (i, j)
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b) diff = std::max(diff, std::abs(L[3 * a + b] - U[3 * b + a]));
      }
    }
    return std::isfinite(big) && diff <= rel * big;
  }

  /// yi = (A x)_i from the blocks on and above the diagonal (row i) and the transposes of the
  /// blocks above the diagonal of rows j < i.
  void row(const BsrMatrix& A, const double* x, Index i, double* yi) const {
    const BsrPattern& P = A.pattern();
    const double* val = A.values().data();
    const Index range[2] = {P.diag[i], P.row_ptr[i + 1]};
    block_row_multiply3(range, P.col.data(), val, x, 0, yi);
#if defined(__AVX2__) && defined(__FMA__)
    // (A_ji^T x_j)_a = sum_c A_ji[c][a] x_j[c]: the rows of A_ji scaled by x_j's entries.
    const __m256i m3 = _mm256_setr_epi64x(-1, -1, -1, 0);
    // Three independent accumulators (one per row of the block), as in the full-row product,
    // so consecutive FMAs do not wait on each other.
    __m256d a0 = _mm256_setzero_pd(), a1 = _mm256_setzero_pd(), a2 = _mm256_setzero_pd();
    for (Index t = lo_ptr_[i]; t < lo_ptr_[i + 1]; ++t) {
      const double* B = val + 9 * static_cast<std::size_t>(lo_pos_[t]);
      const double* xj = x + 3 * static_cast<std::size_t>(lo_row_[t]);
      a0 = _mm256_fmadd_pd(_mm256_maskload_pd(B, m3), _mm256_broadcast_sd(xj), a0);
      a1 = _mm256_fmadd_pd(_mm256_maskload_pd(B + 3, m3), _mm256_broadcast_sd(xj + 1), a1);
      a2 = _mm256_fmadd_pd(_mm256_maskload_pd(B + 6, m3), _mm256_broadcast_sd(xj + 2), a2);
    }
    alignas(32) double l[4];
    _mm256_store_pd(l, _mm256_add_pd(_mm256_add_pd(a0, a1), a2));
    yi[0] += l[0];
    yi[1] += l[1];
    yi[2] += l[2];
#else
    for (Index t = lo_ptr_[i]; t < lo_ptr_[i + 1]; ++t) {
      const double* B = val + 9 * static_cast<std::size_t>(lo_pos_[t]);
      const double* xj = x + 3 * static_cast<std::size_t>(lo_row_[t]);
      for (int a = 0; a < 3; ++a) yi[a] += B[a] * xj[0] + B[3 + a] * xj[1] + B[6 + a] * xj[2];
    }
#endif
  }

 private:
  bool ok_ = false;
  std::vector<Index> lo_ptr_, lo_row_, lo_pos_;  // per row i: rows j < i and positions of (j, i)
};

}  // namespace loom
