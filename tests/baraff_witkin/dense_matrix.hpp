// Shared by the Baraff-Witkin tests: a block matrix as a dense Eigen matrix, for checks against
// an independent dense computation (eigenvalues, products, solves).
#pragma once

#include <Eigen/Dense>

#include "loom/bsr.hpp"

namespace loom_test {

inline Eigen::MatrixXd dense(const loom::BsrMatrix& A) {
  const loom::Index N = 3 * A.rows();
  const std::vector<double> d = A.to_dense();
  Eigen::MatrixXd M(N, N);
  for (loom::Index r = 0; r < N; ++r)
    for (loom::Index c = 0; c < N; ++c) M(r, c) = d[static_cast<std::size_t>(r) * N + c];
  return M;
}

}  // namespace loom_test
