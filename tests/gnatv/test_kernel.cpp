// GNATV per-triangle kernel: rest state, force = -grad energy, exact Jacobian, symmetry,
// definiteness with the PSD projection. Derivatives by complex step (exact to rounding)
// and by central differences.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <complex>
#include <iostream>
#include <random>

#include "loom/kernels/gnatv.hpp"
#include "wool_data.hpp"

using cplx = std::complex<double>;
template <>
struct loom::ScalarReal<cplx> {
  static double get(const cplx& x) { return x.real(); }
};

namespace g = loom::gnatv;
using loom::Curve;
using loom::CurveInterpolation;

namespace {

struct WoolCurves {
  Curve a, b, c;
  g::Curves<double> view;
  explicit WoolCurves(CurveInterpolation kind)
      : a(Curve::build_uniform(wool::weft_start, wool::weft_step, wool::weft, kind, 0.0)),
        b(Curve::build_uniform(wool::warp_start, wool::warp_step, wool::warp, kind, 0.0)),
        c(Curve::build_uniform(wool::shear_start, wool::shear_step, wool::shear, kind)) {
    view = {a.view(), b.view(), c.view()};
  }
};

// A random rest triangle in 2D (either orientation) and a random deformed placement in 3D.
struct Case {
  g::RestTriangle<double> rest;
  double rest2d[3][2];
  double P[3][3];
};

Case random_case(std::mt19937& rng, double stretch, double shear, double noise) {
  std::uniform_real_distribution<double> U(-1, 1);
  Case c;
  for (;;) {
    for (auto& p : c.rest2d) { p[0] = 0.1 * U(rng); p[1] = 0.1 * U(rng); }
    if (g::rest_from_2d(c.rest2d[0], c.rest2d[1], c.rest2d[2], c.rest, 1e-3)) break;
  }
  // Deformation: 2D affine map (stretch/compression along x and y, shear), embedded by
  // a random rotation, plus per-vertex noise.
  const double sx = 1 + stretch * U(rng), sy = 1 + stretch * U(rng), k = shear * U(rng);
  Eigen::Matrix<double, 3, 2> F;
  F << sx, k, 0, sy, 0, 0;
  const Eigen::Matrix3d Q = Eigen::Quaterniond::UnitRandom().toRotationMatrix();
  for (int j = 0; j < 3; ++j) {
    Eigen::Vector3d p = Q * (F * Eigen::Vector2d(c.rest2d[j][0], c.rest2d[j][1]));
    for (int d = 0; d < 3; ++d) c.P[j][d] = p[d] + noise * 0.1 * U(rng) + 0.3 * d;
  }
  return c;
}

double max_abs(const double F[3][3]) {
  double m = 0;
  for (int j = 0; j < 3; ++j)
    for (int k = 0; k < 3; ++k) m = std::max(m, std::fabs(F[j][k]));
  return m;
}

}  // namespace

TEST(GnatvKernel, RestStateHasZeroStrainAndForceForBothOrientations) {
  WoolCurves wc(CurveInterpolation::MonotoneCubic);
  // Counter-clockwise and clockwise copies of the same triangle.
  const double tri[2][3][2] = {{{0, 0}, {0.3, 0.05}, {0.1, 0.2}}, {{0, 0}, {0.1, 0.2}, {0.3, 0.05}}};
  for (int o = 0; o < 2; ++o) {
    g::RestTriangle<double> r;
    ASSERT_TRUE(g::rest_from_2d(tri[o][0], tri[o][1], tri[o][2], r));
    EXPECT_NEAR(r.area, 0.5 * std::fabs(0.3 * 0.2 - 0.05 * 0.1), 1e-15);
    EXPECT_NEAR(r.ru[0] + r.ru[1] + r.ru[2], 0, 1e-13);
    EXPECT_NEAR(r.rv[0] + r.rv[1] + r.rv[2], 0, 1e-13);
    double P[3][3], F[3][3], u[3], v[3], e[3];
    for (int j = 0; j < 3; ++j) { P[j][0] = tri[o][j][0]; P[j][1] = tri[o][j][1]; P[j][2] = 0.0; }
    g::deformation(r, P, u, v);
    EXPECT_NEAR(u[0], 1, 1e-13); EXPECT_NEAR(u[1], 0, 1e-13);
    EXPECT_NEAR(v[0], 0, 1e-13); EXPECT_NEAR(v[1], 1, 1e-13);
    g::strains(u, v, e);
    for (double x : e) EXPECT_NEAR(x, 0, 1e-13);
    EXPECT_NEAR(g::forces(r, wc.view, P, F), 0, 1e-13);
    EXPECT_LT(max_abs(F), 1e-10);
    // Rigid motion keeps it force free.
    const Eigen::Matrix3d Q = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
    for (int j = 0; j < 3; ++j) {
      Eigen::Vector3d p = Q * Eigen::Vector3d(P[j][0], P[j][1], P[j][2]) + Eigen::Vector3d(1, -2, 3);
      for (int d = 0; d < 3; ++d) P[j][d] = p[d];
    }
    g::forces(r, wc.view, P, F);
    EXPECT_LT(max_abs(F), 1e-9);
    EXPECT_LT(g::max_principal_strain(r, P), 1e-9);
  }
}

TEST(GnatvKernel, ForceIsMinusTheEnergyGradient) {
  // Complex step on the energy, for compression, shear and stretch beyond the data
  // (warp data ends at 1.4% strain, weft at 11%, shear at +-0.14).
  for (auto kind : {CurveInterpolation::MonotoneCubic, CurveInterpolation::BSpline}) {
    WoolCurves wc(kind);
    std::mt19937 rng(11);
    double worst = 0, worst_fd = 0;
    for (int trial = 0; trial < 300; ++trial) {
      const double stretch = trial < 100 ? 0.05 : 0.3, shear = trial % 3 == 0 ? 0.4 : 0.1;
      Case c = random_case(rng, stretch, shear, 0.05);
      double F[3][3];
      g::forces(c.rest, wc.view, c.P, F);
      const double scale = max_abs(F) + 1e-12;
      for (int j = 0; j < 3; ++j)
        for (int d = 0; d < 3; ++d) {
          cplx Pc[3][3];
          for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) Pc[a][b] = c.P[a][b];
          const double h = 1e-20;
          Pc[j][d] += cplx(0, h);
          const double dE = g::energy(c.rest, wc.view, Pc).imag() / h;
          worst = std::max(worst, std::fabs(F[j][d] + dE) / scale);
          // Central difference (checks the real-valued energy path too).
          double Pp[3][3], Pm[3][3];
          std::copy(&c.P[0][0], &c.P[0][0] + 9, &Pp[0][0]);
          std::copy(&c.P[0][0], &c.P[0][0] + 9, &Pm[0][0]);
          const double hf = 1e-7;
          Pp[j][d] += hf;
          Pm[j][d] -= hf;
          const double fd = (g::energy(c.rest, wc.view, Pp) - g::energy(c.rest, wc.view, Pm)) / (2 * hf);
          worst_fd = std::max(worst_fd, std::fabs(F[j][d] + fd) / scale);
        }
    }
    std::cout << "[ measured ] kind " << int(kind) << ": force vs -grad energy, complex step " << worst
              << ", central FD " << worst_fd << " (relative to max |F|)\n";
    EXPECT_LT(worst, 1e-12) << "kind " << int(kind);
    EXPECT_LT(worst_fd, 1e-5) << "kind " << int(kind);
  }
}

TEST(GnatvKernel, ExactJacobianMatchesDerivativeOfForce) {
  for (auto kind : {CurveInterpolation::MonotoneCubic, CurveInterpolation::BSpline}) {
    WoolCurves wc(kind);
    std::mt19937 rng(23);
    double worst_cs = 0, worst_fd = 0, worst_sym = 0;
    for (int trial = 0; trial < 300; ++trial) {
      Case c = random_case(rng, trial < 150 ? 0.05 : 0.3, trial % 2 ? 0.4 : 0.1, 0.05);
      double J[3][3][9];
      g::jacobian(c.rest, wc.view, c.P, false, J);
      double scale = 0;
      for (auto& row : J)
        for (auto& b : row)
          for (double x : b) scale = std::max(scale, std::fabs(x));
      for (int i = 0; i < 3; ++i)
        for (int d = 0; d < 3; ++d) {
          cplx Pc[3][3], Fc[3][3];
          for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) Pc[a][b] = c.P[a][b];
          Pc[i][d] += cplx(0, 1e-20);
          g::forces(c.rest, wc.view, Pc, Fc);
          double Pp[3][3], Pm[3][3], Fp[3][3], Fm[3][3];
          std::copy(&c.P[0][0], &c.P[0][0] + 9, &Pp[0][0]);
          std::copy(&c.P[0][0], &c.P[0][0] + 9, &Pm[0][0]);
          const double h = 1e-9;  // the curves are only C1/C2 at knots: keep h small
          Pp[i][d] += h;
          Pm[i][d] -= h;
          g::forces(c.rest, wc.view, Pp, Fp);
          g::forces(c.rest, wc.view, Pm, Fm);
          for (int j = 0; j < 3; ++j)
            for (int r = 0; r < 3; ++r) {
              const double Jx = J[j][i][3 * r + d];
              worst_cs = std::max(worst_cs, std::fabs(Jx - Fc[j][r].imag() / 1e-20) / scale);
              worst_fd = std::max(worst_fd, std::fabs(Jx - (Fp[j][r] - Fm[j][r]) / (2 * h)) / scale);
            }
        }
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i)
          for (int r = 0; r < 3; ++r)
            for (int q = 0; q < 3; ++q)
              worst_sym = std::max(worst_sym, std::fabs(J[j][i][3 * r + q] - J[i][j][3 * q + r]));
    }
    std::cout << "[ measured ] kind " << int(kind) << ": exact Jacobian vs complex step " << worst_cs
              << ", vs central FD " << worst_fd << " (relative to max |J|)\n";
    EXPECT_LT(worst_cs, 1e-10) << "kind " << int(kind);  // rounding in the formula at 30% stretch
    EXPECT_LT(worst_fd, 1e-6) << "kind " << int(kind);
    EXPECT_EQ(worst_sym, 0.0);  // J_ij = J_ji^T exactly (G3)
  }
}

TEST(GnatvKernel, CorrectedShearTermGivesShearStiffness) {
  // NUMERICS.md 2.3 (G1): right triangle with legs 0.1 at rest, linear laws with
  // sigma'_uu = sigma'_vv = 100, sigma'_uv = 30: in-plane eigenvalues of -J are
  // {0, 0, 0, 36.4, 100, 123.6}; the thesis formula gives {0, 0, 0, 0, 70, 130}.
  const Curve lu = Curve::build({-1.0, 1.0}, {-100.0, 100.0}, CurveInterpolation::MonotoneCubic);
  const Curve ls = Curve::build({-1.0, 1.0}, {-30.0, 30.0}, CurveInterpolation::MonotoneCubic);
  const g::Curves<double> cv{lu.view(), lu.view(), ls.view()};
  const double a[2] = {0, 0}, b[2] = {0.1, 0}, c[2] = {0, 0.1};
  g::RestTriangle<double> r;
  ASSERT_TRUE(g::rest_from_2d(a, b, c, r));
  const double P[3][3] = {{0, 0, 0}, {0.1, 0, 0}, {0, 0.1, 0}};
  double J[3][3][9];
  g::jacobian(r, cv, P, false, J);
  Eigen::Matrix<double, 6, 6> K;  // in-plane (x, y) part of -J
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i)
      for (int p = 0; p < 2; ++p)
        for (int q = 0; q < 2; ++q) K(2 * j + p, 2 * i + q) = -J[j][i][3 * p + q];
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> es(K);
  const double expect[6] = {0, 0, 0, 36.4, 100, 123.6};
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(es.eigenvalues()[k], expect[k], 0.05) << k;
}

TEST(GnatvKernel, PsdProjectionOf2x2) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> U(-1, 1);
  for (int t = 0; t < 1000; ++t) {
    double a = U(rng), b = U(rng), c = U(rng);
    Eigen::Matrix2d S;
    S << a, c, c, b;
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(S);
    const Eigen::Vector2d l = es.eigenvalues().cwiseMax(0.0);
    const Eigen::Matrix2d ref = es.eigenvectors() * l.asDiagonal() * es.eigenvectors().transpose();
    g::project_psd_2x2(a, b, c);
    EXPECT_NEAR(a, ref(0, 0), 1e-12);
    EXPECT_NEAR(b, ref(1, 1), 1e-12);
    EXPECT_NEAR(c, ref(0, 1), 1e-12);
  }
}

TEST(GnatvKernel, ProjectedJacobianIsNegativeSemidefiniteUnderCompression) {
  int indefinite_exact = 0;
  for (auto kind : {CurveInterpolation::MonotoneCubic, CurveInterpolation::BSpline}) {
    WoolCurves wc(kind);
    std::mt19937 rng(31);
    for (int trial = 0; trial < 300; ++trial) {
      Case c = random_case(rng, 0.3, 0.3, 0.1);
      // Force compression in at least one direction on most trials.
      for (int j = 0; j < 3; ++j)
        if (trial % 2 == 0) c.P[j][0] *= 0.7;
      for (bool psd : {true, false}) {
        double J[3][3][9];
        g::jacobian(c.rest, wc.view, c.P, psd, J);
        Eigen::Matrix<double, 9, 9> K;
        for (int j = 0; j < 3; ++j)
          for (int i = 0; i < 3; ++i)
            for (int p = 0; p < 3; ++p)
              for (int q = 0; q < 3; ++q) K(3 * j + p, 3 * i + q) = -J[j][i][3 * p + q];
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> es(K);
        const double tol = 1e-10 * std::max(1.0, es.eigenvalues().cwiseAbs().maxCoeff());
        if (psd) EXPECT_GE(es.eigenvalues().minCoeff(), -tol) << "trial " << trial;
        else indefinite_exact += es.eigenvalues().minCoeff() < -tol;
      }
    }
  }
  EXPECT_GT(indefinite_exact, 100);  // the exact Jacobian really is indefinite in these cases
}

TEST(GnatvKernel, NegativeCurveSlopeIsClampedInTheProjectedJacobian) {
  // A B-spline through data with a plateau overshoots: sigma' < 0 between samples. The
  // exact Jacobian then has a negative material stiffness; the projected one must not.
  const std::vector<double> x = {-0.1, 0.0, 0.02, 0.04, 0.06, 0.08}, y = {-50, 0, 100, 104, 108, 400};
  const Curve s = Curve::build(x, y, CurveInterpolation::BSpline);
  ASSERT_LT(s.min_stiffness(), 0.0);
  const Curve sh = Curve::build({-0.2, 0.0, 0.2}, {-20, 0, 20}, CurveInterpolation::MonotoneCubic);
  const g::Curves<double> cv{s.view(), s.view(), sh.view()};
  // Find the strain of the most negative slope and stretch a right triangle there.
  double e_neg = 0, d_min = 0;
  for (int i = 0; i <= 8000; ++i) {
    const double e = 0.08 * i / 8000.0;
    if (s.stiffness(e) < d_min) { d_min = s.stiffness(e); e_neg = e; }
  }
  ASSERT_LT(d_min, 0.0);
  const double lam = std::sqrt(1 + 2 * e_neg);  // eps_uu = e_neg
  const double a[2] = {0, 0}, b[2] = {0.1, 0}, c[2] = {0, 0.1};
  g::RestTriangle<double> r;
  ASSERT_TRUE(g::rest_from_2d(a, b, c, r));
  const double P[3][3] = {{0, 0, 0}, {0.1 * lam, 0, 0}, {0, 0.1, 0}};
  for (bool psd : {false, true}) {
    double J[3][3][9];
    g::jacobian(r, cv, P, psd, J);
    Eigen::Matrix<double, 9, 9> K;
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i)
        for (int p = 0; p < 3; ++p)
          for (int q = 0; q < 3; ++q) K(3 * j + p, 3 * i + q) = -J[j][i][3 * p + q];
    const double lmin = Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>>(K).eigenvalues().minCoeff();
    if (psd) EXPECT_GE(lmin, -1e-10);
    else EXPECT_LT(lmin, -1e-3);
  }
}
