// Stress-strain curves: interpolation, monotonicity, extension past the data, exact energy.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <random>

#include "loom/curves.hpp"
#include "wool_data.hpp"

using loom::Curve;
using loom::CurveError;
using loom::CurveInterpolation;

namespace {

std::vector<Curve> wool_curves(CurveInterpolation kind) {
  return {Curve::build_uniform(wool::weft_start, wool::weft_step, wool::weft, kind, 0.0),
          Curve::build_uniform(wool::warp_start, wool::warp_step, wool::warp, kind, 0.0),
          Curve::build_uniform(wool::shear_start, wool::shear_step, wool::shear, kind)};
}

const CurveInterpolation kKinds[] = {CurveInterpolation::MonotoneCubic, CurveInterpolation::BSpline};

}  // namespace

TEST(Curves, InterpolatesTheSamples) {
  for (auto kind : kKinds)
    for (const Curve& c : wool_curves(kind))
      for (std::size_t k = 0; k < c.size(); ++k)
        EXPECT_NEAR(c.stress(c.strain()[k]), c.samples()[k], 1e-9 * (1 + std::fabs(c.samples()[k])))
            << "kind " << int(kind) << " sample " << k;
}

TEST(Curves, MonotoneVariantHasNonNegativeSlopeEverywhere) {
  for (const Curve& c : wool_curves(CurveInterpolation::MonotoneCubic)) {
    EXPECT_GE(c.min_stiffness(), 0.0);
    const double a = c.strain().front() - 0.05, b = c.strain().back() + 0.05;
    for (int i = 0; i <= 20000; ++i) EXPECT_GE(c.stiffness(a + (b - a) * i / 20000.0), 0.0);
  }
  // Random monotone (non-decreasing, with flat runs) data on an irregular grid.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(0, 1);
  for (int trial = 0; trial < 200; ++trial) {
    const int n = 2 + trial % 15;
    std::vector<double> x(n), y(n);
    x[0] = -U(rng);
    y[0] = -10 * U(rng);
    for (int k = 1; k < n; ++k) {
      x[k] = x[k - 1] + 0.01 + U(rng);
      y[k] = y[k - 1] + (U(rng) < 0.3 ? 0.0 : 100 * std::pow(U(rng), 3));
    }
    const Curve c = Curve::build(x, y, CurveInterpolation::MonotoneCubic);
    EXPECT_GE(c.min_stiffness(), -1e-12 * (1 + std::fabs(y.back() - y.front()))) << "trial " << trial;
    for (int i = 0; i <= 400; ++i) {
      const double e = x.front() + (x.back() - x.front()) * i / 400.0;
      EXPECT_GE(c.stiffness(e), -1e-9) << "trial " << trial;
    }
  }
}

TEST(Curves, BSplineIsTheClampedC2SplineAndReproducesCubics) {
  // A clamped cubic spline reproduces any cubic exactly when given its end slopes.
  auto p = [](double x) { return 2 * x * x * x - 3 * x * x + 0.5 * x + 1; };
  auto dp = [](double x) { return 6 * x * x - 6 * x + 0.5; };
  std::vector<double> x = {-1.0, -0.7, -0.1, 0.0, 0.4, 0.45, 1.2, 2.0}, y;
  for (double v : x) y.push_back(p(v));
  const Curve c = Curve::build(x, y, CurveInterpolation::BSpline, dp(x.front()), dp(x.back()));
  for (int i = 0; i <= 300; ++i) {
    const double e = -1 + 3.0 * i / 300.0;
    EXPECT_NEAR(c.stress(e), p(e), 1e-11);
    EXPECT_NEAR(c.stiffness(e), dp(e), 1e-10);
  }
  // Second derivative continuous at interior knots of the wool curves (C2), unlike the
  // monotone cubic (only C1).
  int jumps_bspline = 0, jumps_monotone = 0;
  for (auto kind : kKinds) {
    const Curve s = wool_curves(kind)[0];
    for (std::size_t k = 1; k + 1 < s.size(); ++k) {
      const double xk = s.strain()[k], h = 1e-7;
      const double left = (s.stiffness(xk - h) - s.stiffness(xk - 2 * h)) / h;
      const double right = (s.stiffness(xk + 2 * h) - s.stiffness(xk + h)) / h;
      const bool jump = std::fabs(left - right) > 1e-3 * (std::fabs(left) + std::fabs(right)) + 1e-3;
      (kind == CurveInterpolation::BSpline ? jumps_bspline : jumps_monotone) += jump;
    }
  }
  EXPECT_EQ(jumps_bspline, 0);
  EXPECT_GT(jumps_monotone, 0);  // the check itself can see a jump
}

TEST(Curves, ConvergenceOrders) {
  // Interpolation error of exp on [0, 1] with n = 9, 17, 33, 65 samples.
  auto err = [](CurveInterpolation kind, int n) {
    std::vector<double> y(n);
    const double h = 1.0 / (n - 1);
    for (int k = 0; k < n; ++k) y[k] = std::exp(k * h);
    const Curve c = Curve::build_uniform(0.0, h, y, kind, 1.0, std::exp(1.0));
    double e = 0;
    for (int i = 0; i <= 5000; ++i) {
      const double x = i / 5000.0;
      e = std::max(e, std::fabs(c.stress(x) - std::exp(x)));
    }
    return e;
  };
  for (auto kind : kKinds) {
    double prev = err(kind, 9);
    for (int n : {17, 33, 65}) {
      const double e = err(kind, n);
      const double order = std::log2(prev / e);
      std::cout << "[ measured ] " << (kind == CurveInterpolation::BSpline ? "bspline" : "monotone_cubic")
                << " n = " << n << ": max error " << e << ", order " << order << "\n";
      if (kind == CurveInterpolation::BSpline) EXPECT_NEAR(order, 4.0, 0.3) << "n " << n;
      else EXPECT_GT(order, 2.7) << "n " << n;  // PCHIP: O(h^3) away from flat data
      prev = e;
    }
  }
}

TEST(Curves, LinearExtensionWithTheEndSlopeNeverNegative) {
  for (auto kind : kKinds)
    for (const Curve& c : wool_curves(kind)) {
      const double x1 = c.strain().back(), y1 = c.samples().back();
      const double x0 = c.strain().front(), y0 = c.samples().front();
      EXPECT_GE(c.right_slope(), 0.0);
      EXPECT_GE(c.left_slope(), 0.0);
      EXPECT_DOUBLE_EQ(c.right_slope(), std::max(0.0, c.slopes().back()));
      for (double d : {1e-4, 0.01, 0.3}) {
        EXPECT_NEAR(c.stress(x1 + d), y1 + c.right_slope() * d, 1e-9 * (1 + std::fabs(y1)));
        EXPECT_NEAR(c.stiffness(x1 + d), c.right_slope(), 1e-9 * c.right_slope());
        EXPECT_NEAR(c.stress(x0 - d), y0 - c.left_slope() * d, 1e-9 * (1 + std::fabs(y0)));
      }
      // Continuous at the ends.
      EXPECT_NEAR(c.stress(x1 * (1 + 1e-12)), c.stress(x1 * (1 - 1e-12)), 1e-6 * (1 + std::fabs(y1)));
    }
  // Data that falls at the end: the extension is flat, not decreasing.
  const Curve c = Curve::build({0.0, 1.0, 2.0, 3.0}, {0.0, 5.0, 6.0, 5.5}, CurveInterpolation::MonotoneCubic);
  EXPECT_EQ(c.right_slope(), 0.0);
  EXPECT_DOUBLE_EQ(c.stress(10.0), 5.5);
  // The B-spline on its default (estimated) end slopes, same data.
  const Curve b = Curve::build({0.0, 1.0, 2.0, 3.0}, {0.0, 5.0, 6.0, 5.5}, CurveInterpolation::BSpline);
  EXPECT_EQ(b.right_slope(), 0.0);
  EXPECT_LT(b.slopes().back(), 0.0);
}

TEST(Curves, EnergyIsTheExactIntegralOfTheStress) {
  for (auto kind : kKinds)
    for (const Curve& c : wool_curves(kind)) {
      EXPECT_EQ(c.energy(0.0), 0.0);
      const double a = c.strain().front() - 0.2, b = c.strain().back() + 0.2;
      double scale = 0;
      for (double s : c.samples()) scale = std::max(scale, std::fabs(s));
      for (int i = 0; i <= 997; ++i) {
        const double e = a + (b - a) * i / 997.0, h = 1e-6;
        const double fd = (c.energy(e + h) - c.energy(e - h)) / (2 * h);
        EXPECT_NEAR(fd, c.stress(e), 1e-6 * (scale + std::fabs(c.stress(e))));
      }
      // Against 3-point Gauss-Legendre per segment (exact for cubics).
      double W = 0;
      const auto& x = c.strain();
      const double g = std::sqrt(0.6);
      for (std::size_t k = 0; k + 1 < x.size(); ++k) {
        const double m = 0.5 * (x[k] + x[k + 1]), r = 0.5 * (x[k + 1] - x[k]);
        W += r * (5.0 / 9 * c.stress(m - g * r) + 8.0 / 9 * c.stress(m) + 5.0 / 9 * c.stress(m + g * r));
      }
      EXPECT_NEAR(c.energy(x.back()) - c.energy(x.front()), W, 1e-10 * (std::fabs(W) + 1));
    }
}

TEST(Curves, BadDataIsRejected) {
  auto kind = CurveInterpolation::MonotoneCubic;
  EXPECT_THROW(Curve::build({0.0}, {0.0}, kind), CurveError);
  EXPECT_THROW(Curve::build({0.0, 1.0, 1.0}, {0.0, 1.0, 2.0}, kind), CurveError);
  EXPECT_THROW(Curve::build({0.0, 2.0, 1.0}, {0.0, 1.0, 2.0}, kind), CurveError);
  EXPECT_THROW(Curve::build({0.0, 1.0}, {0.0, std::nan("")}, kind), CurveError);
  EXPECT_THROW(Curve::build({0.0, INFINITY}, {0.0, 1.0}, kind), CurveError);
  EXPECT_THROW(Curve::build_uniform(0.0, -0.1, {0.0, 1.0}, kind), CurveError);
  EXPECT_THROW(Curve::build_uniform(0.0, 0.0, {0.0, 1.0}, kind), CurveError);
  try {
    Curve::build({0.0, 2.0, 1.0}, {0.0, 1.0, 2.0}, kind);
  } catch (const CurveError& e) {
    EXPECT_EQ(e.sample(), 2);
    EXPECT_NE(std::string(e.what()).find("increasing"), std::string::npos);
  }
}
