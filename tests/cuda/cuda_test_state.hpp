// Shared by the CUDA backend's tests: the start state of a test scene and a run of steps.
#pragma once

#include <random>

#include "common/scene_state.hpp"
#include "loom/integrator.hpp"
#include "loom/scene.hpp"

namespace loom_cuda_test {

/// Masses from the scene's material, corners 0 and nx - 1 pinned, the free vertices moved by
/// up to pert (m) and given velocities up to vel (m/s) from a seeded generator, gravity -9.81 y.
inline void init_perturbed_state(loom::Scene& sc, loom::Index nx, unsigned seed, double pert, double vel) {
  loom_test::init_state(sc);
  loom::State& st = sc.state;
  const loom::Index n = sc.mesh.num_vertices();
  st.pin(0);
  st.pin(nx - 1);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (loom::Index i = 0; i < n; ++i) {
    if (st.pinned[i]) continue;
    for (int a = 0; a < 3; ++a) {
      st.x[3 * i + a] += pert * u(rng);
      st.v[3 * i + a] = vel * u(rng);
    }
  }
  sc.gravity = {0.0, -9.81, 0.0};
}

/// prepare, then `steps` steps of size h.
inline void run(loom::Integrator& integ, loom::Scene& sc, double h, int steps) {
  integ.prepare(sc, h);
  for (int k = 0; k < steps; ++k) integ.step(sc, h);
}

}  // namespace loom_cuda_test
