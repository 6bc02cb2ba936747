// Shared by the CUDA backend's Baraff-Witkin collider tests (test_cuda_bw_colliders,
// test_cuda_mesh_colliders): the solvers that make the two backends agree to rounding.
#pragma once

#include <memory>

#include "device_pcg.hpp"
#include "eigen_pcg.hpp"
#include "loom/scene.hpp"

namespace loom_cuda_test {

/// Both scenes solved by the one filtered_pcg loop at a tight tolerance (1e-13, at most 20000
/// iterations): the CPU plugin's on `cpu`, the device one on `dev`.
inline void tight_pcg(loom::Scene& cpu, loom::Scene& dev) {
  loom::PcgOptions co;
  co.tolerance = 1e-13;
  co.max_iterations = 20000;
  cpu.solver = std::make_unique<loom::EigenPcg>(co);
  loom::cuda::PcgOptions go;
  go.tolerance = 1e-13;
  go.max_iterations = 20000;
  dev.solver = std::make_unique<loom::cuda::CusparsePcg>(go);
}

}  // namespace loom_cuda_test
