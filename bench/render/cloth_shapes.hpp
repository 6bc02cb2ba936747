// Test shapes for renderer benchmarks and figures: a folded cloth (vertical folds, like a
// curtain) on a regular grid.
#pragma once

#include <cmath>
#include <vector>

#include "loom/mesh.hpp"

namespace loom::render {

/// n x n grid of size x size in the xy plane with folds along y: z = amp sin(2 pi folds x / size).
inline Mesh folded_cloth(Index n, double size, double folds, double amp) {
  Mesh m = make_grid(n, n, size, size, GridPlane::XY);
  for (std::size_t i = 0; i < m.positions.size(); i += 3)
    m.positions[i + 2] = amp * std::sin(2.0 * 3.14159265358979 * folds * m.positions[i] / size);
  m.uvs.clear();  // frames of a run carry no UVs: use the planar ones, like `loom render`
  return m;
}

}  // namespace loom::render
