// Exact solution of the relative axial motion of an isolated spring,
//   delta'' = -omega2 delta - 2 beta delta',
// in long double, written independently of loom/kernels/ho.hpp (direct cos/sin, critical and
// two-exponential forms).
#pragma once

#include <cmath>

namespace loom::testing {

struct AxialState {
  long double delta, rate;
};

inline AxialState exact_axial(long double d0, long double v0, long double omega2, long double beta,
                              long double t) {
  const long double disc = omega2 - beta * beta;
  const long double scale = omega2 > 0 ? omega2 : 1.0L;
  if (beta == 0) {
    const long double w = std::sqrt(omega2);
    if (w == 0) return {d0 + v0 * t, v0};
    return {d0 * std::cos(w * t) + v0 / w * std::sin(w * t), v0 * std::cos(w * t) - d0 * w * std::sin(w * t)};
  }
  const long double E = std::exp(-beta * t);
  if (std::fabs(disc) <= 1e-15L * scale) {   // critical
    return {E * (d0 + (v0 + beta * d0) * t), E * (v0 - (beta * v0 + omega2 * d0) * t)};
  }
  if (disc > 0) {
    const long double wd = std::sqrt(disc);
    const long double c = std::cos(wd * t), s = std::sin(wd * t);
    return {E * (d0 * c + (v0 + beta * d0) / wd * s), E * (v0 * c - (omega2 * d0 + beta * v0) / wd * s)};
  }
  const long double sq = std::sqrt(-disc);
  const long double r1 = -beta + sq, r2 = -beta - sq;
  const long double A = (v0 - r2 * d0) / (r1 - r2), B = d0 - A;
  const long double e1 = std::exp(r1 * t), e2 = std::exp(r2 * t);
  return {A * e1 + B * e2, r1 * A * e1 + r2 * B * e2};
}

}  // namespace loom::testing
