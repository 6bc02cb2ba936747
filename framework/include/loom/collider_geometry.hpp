// Triangles that draw the colliders of a scene at a time t (for `loom render`): spheres
// tessellated, planes as a square around the cloth, meshes placed by their rigid motion.
#pragma once

#include <vector>

#include "loom/collider.hpp"

namespace loom {

/// Append the colliders' surfaces at time t as a triangle soup: 9 floats per triangle in
/// `positions`, a unit normal per vertex in `normals`. A plane is drawn as a square of side
/// `plane_size` centred on the projection of `focus` (e.g. the cloth's centre) onto it.
void collider_triangles(const ColliderSet& colliders, double t, const double focus[3], double plane_size,
                        std::vector<float>& positions, std::vector<float>& normals);

}  // namespace loom
