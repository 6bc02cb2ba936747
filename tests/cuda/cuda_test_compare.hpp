// Shared by the CUDA backend's tests: comparing device results with the CPU's.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "device.hpp"

namespace loom_cuda_test {

/// Max-norm relative difference max|a - b| / max|b| (max|a - b| when b is zero).
inline double rel_diff(const std::vector<double>& a, const std::vector<double>& b) {
  EXPECT_EQ(a.size(), b.size());
  double num = 0, den = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    num = std::max(num, std::fabs(a[k] - b[k]));
    den = std::max(den, std::fabs(b[k]));
  }
  return den > 0 ? num / den : num;
}

/// A device vector as host doubles.
template <class T>
std::vector<double> to_host(const loom::cuda::DVec<T>& d) {
  std::vector<double> h;
  std::vector<T> stage;
  loom::cuda::download(d, h, stage);
  return h;
}

}  // namespace loom_cuda_test
