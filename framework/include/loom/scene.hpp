// Scene: what a scene file builds (mesh, state, material, solver), handed to the integrator.
#pragma once

#include <array>
#include <memory>
#include <string>

#include "loom/bsr.hpp"
#include "loom/collider.hpp"
#include "loom/linear_solver.hpp"
#include "loom/material.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "loom/pins.hpp"
#include "loom/self_collision.hpp"
#include "loom/state.hpp"

namespace loom {

struct Scene {
  std::string source;                      ///< scene file path (for messages)
  Mesh mesh;
  State state;
  std::array<double, 3> gravity{0.0, -9.81, 0.0};
  std::unique_ptr<Material> material;
  std::unique_ptr<LinearSolver> solver;    ///< set only when the integrator needs one
  ColliderSet colliders;                   ///< empty unless the scene declares colliders
  PinSet pins;                             ///< pin groups (motions, reactions); empty: fixed pins only
  std::unique_ptr<SelfCollision> self_collision;  ///< null unless the scene declares self_collision
  std::string backend = "cpu";
  int threads = 1;                         ///< resolved thread count (loom/threads.hpp)
};

}  // namespace loom
