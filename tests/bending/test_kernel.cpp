// The hinge kernel (kernels/bending.hpp): force = -grad E by complex step and central
// differences, Jacobian (exact) against the complex-step derivative of the force, the
// Gauss-Newton Jacobian PSD, zero force at the rest angle, invariance under rigid motions.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <complex>
#include <random>

#include "loom/kernels/bending.hpp"

using cplx = std::complex<double>;

// Complex-step arithmetic for the kernel: atan2 and sqrt analytic in the imaginary part.
template <>
struct loom::bending::HingeMath<cplx> {
  static cplx atan2(const cplx& s, const cplx& c) {
    const double a = std::atan2(s.real(), c.real());
    const double d = (c.real() * s.imag() - s.real() * c.imag()) / (s.real() * s.real() + c.real() * c.real());
    return {a, d};
  }
  static cplx sqrt(const cplx& a) { return std::sqrt(a); }
  static double value(const cplx& a) { return a.real(); }
};

namespace {

using loom::bending::RestHinge;

// A random non-flat hinge: edge of length ~1, wings at random heights and sides.
void random_hinge(std::mt19937& rng, double X[4][3]) {
  std::uniform_real_distribution<double> U(-1, 1);
  for (;;) {
    const double pts[4][3] = {{0, 0, 0}, {1, 0, 0}, {0.5, 1, 0}, {0.5, -1, 0}};
    for (int a = 0; a < 4; ++a)
      for (int k = 0; k < 3; ++k) X[a][k] = pts[a][k] + 0.6 * U(rng);
    double th, g[4][3];
    if (loom::bending::angle_gradient(X, th, g) && std::fabs(th) > 0.05 && std::fabs(th) < 2.8) return;
  }
}

double max_abs(const double F[4][3]) {
  double m = 0;
  for (int a = 0; a < 4; ++a)
    for (int k = 0; k < 3; ++k) m = std::max(m, std::fabs(F[a][k]));
  return m;
}

}  // namespace

TEST(BendingKernel, ForceIsMinusEnergyGradientByComplexStepAndCentralDifferences) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1, 1);
  double worst_cs = 0, worst_fd = 0;
  for (int trial = 0; trial < 200; ++trial) {
    double X[4][3], F[4][3];
    random_hinge(rng, X);
    const RestHinge<double> h{0.3 + U(rng) * 0.2, 0.7 * U(rng)};
    loom::bending::forces(h, X, F);
    const double scale = max_abs(F);
    ASSERT_GT(scale, 0);
    for (int a = 0; a < 4; ++a)
      for (int k = 0; k < 3; ++k) {
        cplx Xc[4][3];
        for (int b = 0; b < 4; ++b)
          for (int q = 0; q < 3; ++q) Xc[b][q] = X[b][q];
        const double step = 1e-30;
        Xc[a][k] += cplx(0, step);
        const double dE = loom::bending::energy(h, Xc).imag() / step;
        worst_cs = std::max(worst_cs, std::fabs(F[a][k] + dE) / scale);
        const double eta = 1e-6;
        double Xp[4][3], Xm[4][3];
        std::copy(&X[0][0], &X[0][0] + 12, &Xp[0][0]);
        std::copy(&X[0][0], &X[0][0] + 12, &Xm[0][0]);
        Xp[a][k] += eta;
        Xm[a][k] -= eta;
        const double fd = (loom::bending::energy(h, Xp) - loom::bending::energy(h, Xm)) / (2 * eta);
        worst_fd = std::max(worst_fd, std::fabs(F[a][k] + fd) / scale);
      }
  }
  EXPECT_LT(worst_cs, 1e-13);
  EXPECT_LT(worst_fd, 1e-7);
}

TEST(BendingKernel, ExactJacobianMatchesComplexStepOfTheForce) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> U(-1, 1);
  double worst = 0, worst_sym = 0;
  for (int trial = 0; trial < 200; ++trial) {
    double X[4][3], J[4][4][9];
    random_hinge(rng, X);
    const RestHinge<double> h{0.5, 0.8 * U(rng)};
    loom::bending::jacobian(h, X, true, J);
    double scale = 0;
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        for (int q = 0; q < 9; ++q) scale = std::max(scale, std::fabs(J[a][b][q]));
    for (int b = 0; b < 4; ++b)
      for (int c = 0; c < 3; ++c) {
        cplx Xc[4][3], Fc[4][3];
        for (int p = 0; p < 4; ++p)
          for (int q = 0; q < 3; ++q) Xc[p][q] = X[p][q];
        const double step = 1e-30;
        Xc[b][c] += cplx(0, step);
        loom::bending::forces(h, Xc, Fc);
        for (int a = 0; a < 4; ++a)
          for (int r = 0; r < 3; ++r)
            worst = std::max(worst, std::fabs(J[a][b][3 * r + c] - Fc[a][r].imag() / step) / scale);
      }
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c)
            worst_sym = std::max(worst_sym, std::fabs(J[a][b][3 * r + c] - J[b][a][3 * c + r]) / scale);
  }
  EXPECT_LT(worst, 1e-12);
  EXPECT_LT(worst_sym, 1e-13);
}

TEST(BendingKernel, GaussNewtonJacobianIsNegativeSemidefiniteAndExactOneIsNotAlways) {
  std::mt19937 rng(5);
  int exact_indefinite = 0;
  for (int trial = 0; trial < 100; ++trial) {
    double X[4][3], J[4][4][9];
    random_hinge(rng, X);
    const RestHinge<double> h{1.0, 0.0};
    for (bool exact : {false, true}) {
      loom::bending::jacobian(h, X, exact, J);
      Eigen::Matrix<double, 12, 12> K;
      for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b)
          for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) K(3 * a + r, 3 * b + c) = -J[a][b][3 * r + c];
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 12, 12>> es(K);
      const double lmax = es.eigenvalues().maxCoeff(), lmin = es.eigenvalues().minCoeff();
      if (!exact) EXPECT_GE(lmin, -1e-12 * lmax) << "trial " << trial;
      else if (lmin < -1e-8 * lmax) ++exact_indefinite;
    }
  }
  // Away from the rest angle the exact stiffness is indefinite for some hinges: that is why
  // the implicit solve uses the Gauss-Newton term by default.
  EXPECT_GT(exact_indefinite, 0);
}

TEST(BendingKernel, ZeroForceAtTheRestAngleAndFlatHingeHasZeroAngle) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 50; ++trial) {
    double X[4][3], g[4][3], th, F[4][3];
    random_hinge(rng, X);
    loom::bending::angle_gradient(X, th, g);
    const RestHinge<double> h{2.0, th};
    EXPECT_EQ(loom::bending::forces(h, X, F), 0.0);
    EXPECT_EQ(max_abs(F), 0.0);
  }
  const double flat[4][3] = {{0, 0, 0}, {1, 0, 0}, {0.3, 0.8, 0}, {0.6, -0.9, 0}};
  double th, g[4][3];
  ASSERT_TRUE(loom::bending::angle_gradient(flat, th, g));
  EXPECT_EQ(th, 0.0);
  // Lifting both wings by the same small amount folds the hinge by +(dz/hA + dz/hB).
  double up[4][3] = {{0, 0, 0}, {1, 0, 0}, {0.3, 0.8, 1e-7}, {0.6, -0.9, 1e-7}};
  loom::bending::angle_gradient(up, th, g);
  EXPECT_NEAR(th, 1e-7 / 0.8 + 1e-7 / 0.9, 1e-18);
}

TEST(BendingKernel, InvariantUnderRigidMotions) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> U(-1, 1);
  for (int trial = 0; trial < 50; ++trial) {
    double X[4][3], F[4][3];
    random_hinge(rng, X);
    const RestHinge<double> h{0.7, 0.3 * U(rng)};
    const double E = loom::bending::forces(h, X, F);
    const Eigen::Matrix3d R = Eigen::Quaterniond(Eigen::Vector4d(U(rng), U(rng), U(rng), U(rng)).normalized())
                                  .toRotationMatrix();
    const Eigen::Vector3d t(U(rng) * 10, U(rng) * 10, U(rng) * 10);
    double Y[4][3], G[4][3];
    for (int a = 0; a < 4; ++a) {
      const Eigen::Vector3d y = R * Eigen::Vector3d(X[a][0], X[a][1], X[a][2]) + t;
      for (int k = 0; k < 3; ++k) Y[a][k] = y[k];
    }
    const double E2 = loom::bending::forces(h, Y, G);
    EXPECT_NEAR(E2, E, 1e-12 * std::max(1.0, E));
    Eigen::Vector3d sum = Eigen::Vector3d::Zero(), torque = Eigen::Vector3d::Zero();
    for (int a = 0; a < 4; ++a) {
      const Eigen::Vector3d f(F[a][0], F[a][1], F[a][2]), g(G[a][0], G[a][1], G[a][2]);
      EXPECT_LT((R * f - g).norm(), 1e-11 * (1 + max_abs(F)));
      sum += f;
      torque += Eigen::Vector3d(X[a][0], X[a][1], X[a][2]).cross(f);
    }
    // Momentum and angular momentum are conserved: no net force or torque.
    EXPECT_LT(sum.norm(), 1e-12 * (1 + max_abs(F)));
    EXPECT_LT(torque.norm(), 1e-12 * (1 + max_abs(F)));
  }
}

TEST(BendingKernel, DegenerateHingeGivesZeroInsteadOfNaN) {
  const double X[4][3] = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0.5, -1, 0}};  // wing A on the edge line
  double F[4][3], J[4][4][9];
  const RestHinge<double> h{1.0, 0.2};
  EXPECT_EQ(loom::bending::forces(h, X, F), 0.0);
  EXPECT_EQ(max_abs(F), 0.0);
  loom::bending::jacobian(h, X, true, J);
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b)
      for (int q = 0; q < 9; ++q) EXPECT_EQ(J[a][b][q], 0.0);
}

TEST(BendingKernel, StiffnessByEdgeAngleInterpolatesAndFolds) {
  using loom::bending::stiffness_at_edge_angle;
  const double pi = 3.14159265358979323846;
  // Edge along the weft -> first value; 45 degrees -> bias; along the warp -> last value.
  EXPECT_DOUBLE_EQ(stiffness_at_edge_angle(0.0, 1.0, 2.0, 5.0), 1.0);
  EXPECT_DOUBLE_EQ(stiffness_at_edge_angle(pi / 4, 1.0, 2.0, 5.0), 2.0);
  EXPECT_DOUBLE_EQ(stiffness_at_edge_angle(pi / 2, 1.0, 2.0, 5.0), 5.0);
  EXPECT_DOUBLE_EQ(stiffness_at_edge_angle(pi / 8, 1.0, 2.0, 5.0), 1.5);
  EXPECT_DOUBLE_EQ(stiffness_at_edge_angle(3 * pi / 8, 1.0, 2.0, 5.0), 3.5);
  // An edge has no sign and the cloth is symmetric about weft and warp.
  for (double phi : {0.1, 0.5, 1.2})
    for (double other : {-phi, pi - phi, pi + phi, -pi + phi})
      EXPECT_NEAR(stiffness_at_edge_angle(other, 1.0, 2.0, 5.0), stiffness_at_edge_angle(phi, 1.0, 2.0, 5.0), 1e-12);
}
