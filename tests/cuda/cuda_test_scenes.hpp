// Shared by the CUDA backend's collider tests (test_cuda_colliders, test_cuda_mesh_colliders):
// a small mass-spring cloth falling onto the colliders.
#pragma once

#include <memory>
#include <random>

#include "common/scene_state.hpp"
#include "loom/mesh.hpp"
#include "loom/scene.hpp"
#include "mass_spring.hpp"

namespace loom_cuda_test {

/// A 0.6 m mass-spring cloth (nx x nx, xz plane) centred over (cx, cz), its plane at height y0,
/// falling at vy and drifting along x at vx, every velocity component perturbed by up to
/// 0.02 m/s from a generator seeded with `seed`; vertex 0 pinned; the scene's colliders `cols`.
inline std::unique_ptr<loom::Scene> falling_cloth(const loom::ColliderSet& cols, loom::Index nx, double cx, double y0,
                                                  double cz, double vx, double vy, unsigned seed) {
  using namespace loom;
  auto sc = std::make_unique<Scene>();
  sc->source = "<test>";
  sc->mesh = make_grid(nx, nx, 0.6, 0.6, GridPlane::XZ);
  for (Index i = 0; i < sc->mesh.num_vertices(); ++i) {
    sc->mesh.positions[3 * i] += cx - 0.3;
    sc->mesh.positions[3 * i + 1] += y0;
    sc->mesh.positions[3 * i + 2] += cz + 0.3;  // the grid runs along -z from its origin
  }
  sc->material = std::make_unique<mass_spring::MassSpringMaterial>(
      Params::from_string("stiffness: {structural: 200, shear: 200, bend: 20}\ndamping: 0.0005\ndensity: 0.1\n", "<test>"),
      sc->mesh);
  loom_test::init_state(*sc);
  State& st = sc->state;
  st.pin(0);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (Index i = 1; i < st.size(); ++i) {
    st.v[3 * i] = vx + 0.02 * u(rng);
    st.v[3 * i + 1] = vy + 0.02 * u(rng);
    st.v[3 * i + 2] = 0.02 * u(rng);
  }
  sc->colliders = cols;
  return sc;
}

}  // namespace loom_cuda_test
