// `loom render`'s framing: bounds of the whole sequence for the camera, and the ground.
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "loom/collider.hpp"
#include "loom/params.hpp"
#include "loom/registry.hpp"
#include "loom/renderer.hpp"

namespace loom::cli {

struct Framing {
  double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};  ///< bounds of the cloth over all frames
  double center[3] = {0, 0, 0};                  ///< their centre
  double plane_size = 1.0;                       ///< a plane collider's drawn square (2 x the diagonal)
  bool ground = false;                           ///< a ground is drawn
  double ground_point[3] = {0, 0, 0}, up[3] = {0, 1, 0};
};

/// Read every frame once (positions and time) for the bounds of the cloth over the whole run
/// (render.fit: sequence, the default; first_frame keeps the camera of the first frame) and
/// the lowest point along up = -gravity of the cloth and the colliders (render.ground: true,
/// the default, unless the scene has a plane collider, which is its ground). Calls the
/// renderer module's optional fit-camera and ground entry points (renderer.hpp).
Framing frame_sequence(const std::vector<std::filesystem::path>& frames,
                       const std::function<void(const std::filesystem::path&, std::vector<double>&, double*)>& read,
                       const Params& root, const Params& render, const ColliderSet& colliders,
                       const Registry& registry, const std::string& type, Renderer* renderer);

}  // namespace loom::cli
