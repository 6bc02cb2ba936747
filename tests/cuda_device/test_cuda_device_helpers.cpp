// The CUDA backend's host/device transfer and reduction helpers (device.hpp) on empty and
// non-empty vectors, through Thrust's OpenMP device system. Empty vectors once made Thrust bind
// a reference to null (found by UBSan in upload(), download() and dot()); under the sanitizer
// preset this test fails if that comes back. Expected values are computed on the host.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "device.hpp"

using namespace loom;
using namespace loom::cuda;

TEST(CudaDeviceHelpers, EmptyVectorsTransferAndReduceToNothing) {
  const std::vector<double> none;
  DVec<double> a(3, 1.0), b;
  upload(none, a);  // replaces the old contents
  EXPECT_EQ(a.size(), 0u);
  const std::vector<float> none_f;
  DVec<double> c(2, 5.0);
  upload(none_f, c);  // the converting path
  EXPECT_EQ(c.size(), 0u);
  EXPECT_EQ(dot(a, b), 0.0);
  std::vector<double> host(4, 7.0), stage;
  download(a, host, stage);
  EXPECT_TRUE(host.empty());
  DVec<float> f;
  std::vector<float> stage_f(2);
  download(f, host, stage_f);
  EXPECT_TRUE(host.empty());
  fill(a, 2.0);
  EXPECT_EQ(a.size(), 0u);
  EXPECT_EQ(reduce_sum<double>(0, [](Index) { return 1.0; }), 0.0);
}

TEST(CudaDeviceHelpers, NonEmptyVectorsMatchTheHost) {
  for (Index n : {Index(1), Index(5), Index(10000)}) {  // below and above the serial threshold
    std::vector<double> x(n), y(n);
    double expect = 0;
    for (Index i = 0; i < n; ++i) {
      x[i] = 0.5 * double(i) - 3.0;
      y[i] = 1.0 / double(i + 1);
      expect += x[i] * y[i];
    }
    DVec<double> dx, dy;
    upload(x, dx);
    upload(y, dy);
    EXPECT_NEAR(dot(dx, dy), expect, 1e-12 * (1.0 + std::abs(expect))) << n;
    std::vector<double> back, stage;
    download(dx, back, stage);
    EXPECT_EQ(back, x) << n;
    // float storage: values that are exact in float survive the round trip exactly
    std::vector<double> small(n);
    for (Index i = 0; i < n; ++i) small[i] = double(i % 64) * 0.25;
    DVec<float> df;
    upload(small, df);
    std::vector<float> stage_f;
    download(df, back, stage_f);
    EXPECT_EQ(back, small) << n;
    fill(dx, 2.0);
    download(dx, back, stage);
    EXPECT_EQ(back, std::vector<double>(n, 2.0)) << n;
  }
}
