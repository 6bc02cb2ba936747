// Renderer: draws cloth frames to images. Used by `loom render`; not part of a run.
#pragma once

#include <span>
#include <string>

#include "loom/mesh.hpp"
#include "loom/params.hpp"

namespace loom {

class Renderer {
 public:
  virtual ~Renderer() = default;
  virtual std::string name() const = 0;
  /// Called once with the mesh of the first frame (topology is fixed for a run).
  virtual void begin(const Mesh& mesh) = 0;
  /// Render positions x (3n) of the mesh given to begin() into an image file at png_path.
  virtual void render(std::span<const double> x, const std::string& png_path) = 0;
};

}  // namespace loom
