// Shared helpers of the bending tests.
#pragma once

#include <memory>
#include <string>

#include "loom/bending.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "mass_spring.hpp"

namespace bending_test {

/// mass_spring on the mesh edges (membrane) with hinge bending from a YAML bending block.
inline std::unique_ptr<loom::BentMaterial> springs_with_bending(const loom::Mesh& mesh, const std::string& bending_yaml,
                                                                double k = 1e4, double density = 0.1) {
  auto p = loom::Params::from_string("stencil: mesh_edges\nstiffness: " + std::to_string(k) +
                                         "\ndensity: " + std::to_string(density) + "\n",
                                     "<test>");
  auto membrane = std::make_unique<loom::mass_spring::MassSpringMaterial>(p, mesh);
  p.check_unused();
  const auto b = loom::Params::from_string(bending_yaml, "<bending>");
  return std::make_unique<loom::BentMaterial>(std::move(membrane), mesh, loom::read_bending_options(b));
}

}  // namespace bending_test
