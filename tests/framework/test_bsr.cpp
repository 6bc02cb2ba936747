#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "loom/bsr.hpp"

TEST(Bsr, PatternFromPairsIsSortedSymmetricWithDiagonal) {
  const std::vector<std::array<loom::Index, 2>> pairs = {{0, 2}, {2, 0}, {1, 2}, {0, 2}, {3, 3}};
  const auto p = loom::BsrPattern::from_pairs(4, pairs);
  EXPECT_EQ(p.nnz_blocks(), 4 + 4);  // diagonal + (0,2),(2,0),(1,2),(2,1)
  for (loom::Index i = 0; i < 4; ++i) {
    EXPECT_EQ(p.col[p.diag[i]], i);
    for (loom::Index k = p.row_ptr[i] + 1; k < p.row_ptr[i + 1]; ++k) EXPECT_LT(p.col[k - 1], p.col[k]);
  }
  EXPECT_GE(p.find(2, 1), 0);
  EXPECT_EQ(p.find(0, 1), -1);
  EXPECT_EQ(p.find(7, 1), -1);
}

TEST(Bsr, MultiplyMatchesDense) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  const loom::Index n = 30;
  std::vector<std::array<loom::Index, 2>> pairs;
  for (int k = 0; k < 60; ++k) pairs.push_back({static_cast<loom::Index>(rng() % n), static_cast<loom::Index>(rng() % n)});
  const auto p = loom::BsrPattern::from_pairs(n, pairs);
  loom::BsrMatrix A(&p);
  for (double& v : A.values()) v = u(rng);
  std::vector<double> x(3 * n), y(3 * n);
  for (double& v : x) v = u(rng);
  A.multiply(x, y);
  const auto D = A.to_dense();
  for (int r = 0; r < 3 * n; ++r) {
    double s = 0;
    for (int c = 0; c < 3 * n; ++c) s += D[r * 3 * n + c] * x[c];
    EXPECT_NEAR(y[r], s, 1e-12);
  }
  EXPECT_GT(A.asymmetry(), 0.1);  // random values are not symmetric
  A.set_zero();
  for (double v : A.values()) EXPECT_EQ(v, 0.0);
}

TEST(Filter, ProjectorsAndComplement) {
  loom::Filter S;
  S.reset(3);
  S.constrain_all(0);
  const double p[3] = {0, 0, 2.0};  // not unit: normalised inside
  S.constrain_direction(1, p);
  std::vector<double> y = {1, 2, 3, 4, 5, 6, 7, 8, 9};
  auto z = y;
  S.apply(y);
  EXPECT_EQ(y[0], 0.0);
  EXPECT_EQ(y[2], 0.0);
  EXPECT_DOUBLE_EQ(y[3], 4.0);
  EXPECT_DOUBLE_EQ(y[5], 0.0);
  EXPECT_DOUBLE_EQ(y[8], 9.0);
  S.apply_complement(z);
  EXPECT_DOUBLE_EQ(z[0], 1.0);
  EXPECT_DOUBLE_EQ(z[3], 0.0);
  EXPECT_DOUBLE_EQ(z[5], 6.0);
  EXPECT_DOUBLE_EQ(z[8], 0.0);
  EXPECT_EQ(S.free_dofs(1), 2);
  // constraining the same direction again changes nothing; a second one leaves 1 DOF
  S.constrain_direction(1, p);
  EXPECT_EQ(S.free_dofs(1), 2);
  const double q[3] = {1, 0, 1};
  S.constrain_direction(1, q);
  EXPECT_EQ(S.free_dofs(1), 1);
  std::vector<double> w = {0, 0, 0, 1, 1, 1, 0, 0, 0};
  S.apply(w);
  EXPECT_NEAR(w[3], 0.0, 1e-15);
  EXPECT_NEAR(w[4], 1.0, 1e-15);
}
