// Linked into test_cuda_gpu only (the CUDA backend's tests built by nvcc against the real
// module, CTest label `gpu`): a global test environment that skips every test, with the
// reason, when the CUDA runtime finds no usable device (cudaGetDeviceCount fails or returns 0).
// The tests themselves then never touch the device.
#include <gtest/gtest.h>

#include <string>

#include "seam.hpp"

namespace {

class RequireGpu final : public ::testing::Environment {
 public:
  void SetUp() override {
    std::string why;
    const int n = loom::cuda::seam_device_count(why);
    if (n <= 0)
      GTEST_SKIP() << "no usable CUDA device (" << why
                   << "): the gpu-labelled tests need an NVIDIA GPU and driver; run scripts/gpu-check.sh on a GPU "
                      "machine (docs/plugins/cuda.md)";
  }
};

[[maybe_unused]] ::testing::Environment* const kRequireGpu = ::testing::AddGlobalTestEnvironment(new RequireGpu);

}  // namespace
