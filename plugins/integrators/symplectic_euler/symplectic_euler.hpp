// symplectic_euler: v += h (w f(x, v) + g) for free vertices, then x += h v (all vertices;
// pinned ones move with their prescribed velocity). One force evaluation per step. A spring
// material (Material::springs() not null) takes the fused path: one pass over the springs that
// updates each vertex as soon as its force is complete (loom/explicit_springs.hpp).
#pragma once

#include <string>
#include <vector>

#include "loom/explicit_springs.hpp"
#include "loom/integrator.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"
#include "loom/vertex_order.hpp"

namespace loom::symplectic_euler {

/// The keys of symplectic_euler: reorder, merge_springs (dt, substeps: the framework's).
const ParamSpec& spec();

class SymplecticEuler final : public Integrator {
 public:
  explicit SymplecticEuler(const Params& p);
  std::string name() const override { return "symplectic_euler"; }
  void prepare(Scene& scene, double h) override;
  void step(Scene& scene, double h) override;
  StepStats last_step() const override { return stats_; }
  /// Whether the step runs the fused spring path.
  bool fused() const { return sweep_source_ != nullptr; }
  /// Whether the fused path runs in an internal vertex order (key `reorder`).
  bool reordered() const { return !order_.identity(); }
  /// Whether the fused path runs the grouped, windowed sweep (loom/spring_groups.hpp).
  bool windowed() const { return fused() && sweep_.grouped; }
  ReorderMode reorder_mode() const { return reorder_; }
  /// Springs the fused path folded into others (key `merge_springs`; 0 before prepare()).
  Index merged_springs() const { return fused() ? sweep_.merged : 0; }
  /// Springs the fused path steps (after merging).
  Index swept_springs() const { return fused() ? sweep_.size() : 0; }

 private:
  void generic_step(Scene& scene, double h);
  std::vector<double> f_;
  SpringSweep<double> sweep_;
  const SpringSet* sweep_source_ = nullptr;
  ReorderMode reorder_ = ReorderMode::Auto;
  VertexOrder order_;                   ///< internal vertex k is user vertex order_.perm[k]
  std::vector<double> xp_, vp_, wp_;    ///< state in the internal order (reordered runs only)
  StepStats stats_;
};

}  // namespace loom::symplectic_euler
