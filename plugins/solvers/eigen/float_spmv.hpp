// The filtered PCG's SpMV from a float copy of A (PcgOptions::float_spmv, `spmv_storage: float`):
// the 3x3 blocks are stored as 9 floats (36 bytes instead of 72) and widened to double in the
// product, so the SpMV reads about half the bytes (the column indices stay) while the vector
// and every sum stay double. The copy A_f = fl32(A) is exactly symmetric when A is (rounding is
// elementwise), so the iteration is CG on A_f; the start and the stopping rule use the double A
// (filtered_pcg.hpp restarts from the true residual when the two drift apart), so the answer
// still meets the tolerance on A. Each product entry differs from the double one by at most
// 2^-24 sum_j |A_ij| |c_j| plus double rounding (tests/sa_amg/test_float_spmv.cpp).
#pragma once

#include <cstddef>
#include <vector>

#include "loom/common.hpp"
#include "block_row.hpp"

namespace loom {

/// af = float(values) (9 per block) followed by 4 zeros of padding (kept for the layout;
/// block_row_multiply3<float> reads a block's last row with a masked load, nothing past it).
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

}  // namespace loom
