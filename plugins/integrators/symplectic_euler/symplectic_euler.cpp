#include "symplectic_euler.hpp"

#include <stdexcept>

#include "loom/material.hpp"
#include "se_update.hpp"

namespace loom::symplectic_euler {

const ParamSpec& spec() {
  static const ParamSpec spec = [] {
    ParamSpec s("symplectic_euler", "explicit symplectic Euler");
    s.choice("reorder", "auto", {"auto", "none", "rcm"}).backends({"cpu"}).help(
        "vertex order of the fused spring step: rcm renumbers the vertices internally (reverse Cuthill-McKee) so "
        "that springs join nearby vertices; results stay in the mesh's numbering. auto: rcm for meshes of at least "
        "16384 vertices whose spring span it shrinks 4x or more; none: the mesh's order");
    s.flag("merge_springs", SpringSweep<double>::kMergeDuplicatesDefault).backends({"cpu", "cuda"}).help(kMergeSpringsHelp);
    declare_device_keys(s);  // precision, host_sync_every: backend cuda (one spec for both backends)
    return s;
  }();
  return spec;
}

SymplecticEuler::SymplecticEuler(const Params& p) {
  // dt and substeps are the framework's.
  if (p.valid()) {
    if (p.has("type")) p.mark_used("type");
    const ParamReader r(p, spec());
    reorder_ = parse_reorder_mode(r.text("reorder"));
    sweep_.merge_duplicates = r.flag("merge_springs");
  }
  stats_.force_evaluations = 1;
}

void SymplecticEuler::prepare(Scene& scene, double h) {
  if (!scene.material)
    throw InputError(scene.source + ": symplectic_euler needs a material; add a material: section to the scene");
  if (!(h > 0)) throw InputError(scene.source + ": symplectic_euler needs dt > 0");
  const State& s = scene.state;
  const std::size_t n = static_cast<std::size_t>(s.size());
  if (s.x.size() != 3 * n || s.v.size() != 3 * n || s.inv_mass.size() != n)
    throw std::logic_error("symplectic_euler: state arrays have inconsistent sizes");
  f_.assign(3 * n, 0.0);
  const SpringSet* set = scene.material->springs();
  if (set && (set != sweep_source_ || sweep_.n != s.size() || sweep_.source_size != set->size())) {
    order_ = choose_vertex_order(reorder_, s.size(), set->i, set->j);
    if (order_.identity()) {
      sweep_.build(s.size(), *set);
    } else {
      SpringSet internal = *set;
      for (Index& a : internal.i) a = order_.inv[a];
      for (Index& b : internal.j) b = order_.inv[b];
      sweep_.build(s.size(), internal);
    }
  }
  if (!set) order_ = VertexOrder{};
  sweep_source_ = set;
  if (!order_.identity()) {
    xp_.assign(3 * n, 0.0);
    vp_.assign(3 * n, 0.0);
    wp_.resize(n);
    gather_vertices<1>(order_, s.inv_mass.data(), wp_.data());
  } else {
    xp_.clear();
    vp_.clear();
    wp_.clear();
  }
}

void SymplecticEuler::step(Scene& scene, double h) {
  State& s = scene.state;
  const Index n = s.size();
  if (f_.size() != 3 * static_cast<std::size_t>(n))
    throw std::logic_error("symplectic_euler: step() before prepare(), or the vertex count changed");
  if (sweep_source_) {
    // Fused: forces and the vertex update in one pass (f_ is zero between steps).
    if (scene.material->springs() != sweep_source_) throw std::logic_error("symplectic_euler: material changed after prepare()");
    const double g[3] = {scene.gravity[0], scene.gravity[1], scene.gravity[2]};
    if (order_.identity()) {
      se_step_springs(sweep_, s.x.data(), s.v.data(), s.inv_mass.data(), f_.data(), h, g);
    } else {   // on copies in the internal order (3 parallel regions)
      gather_state(order_, s.x.data(), s.v.data(), xp_.data(), vp_.data());
      se_step_springs(sweep_, xp_.data(), vp_.data(), wp_.data(), f_.data(), h, g);
      scatter_state(order_, xp_.data(), vp_.data(), s.x.data(), s.v.data());
    }
  } else {
    generic_step(scene, h);
  }
  // Moving pins: exactly the prescribed positions and velocities at the end of the step.
  scene.pins.apply(s, s.time + h);
  stats_ = StepStats{};
  stats_.force_evaluations = 1;
  finish_step(s, h);
}

void SymplecticEuler::generic_step(Scene& scene, double h) {
  State& s = scene.state;
  const Index n = s.size();
  scene.material->compute_forces(s.x, s.v, f_);
  double* x = s.x.data();
  double* v = s.v.data();
  const double* f = f_.data();
  const double* w = s.inv_mass.data();
  const double g0 = scene.gravity[0], g1 = scene.gravity[1], g2 = scene.gravity[2];
#pragma omp parallel for schedule(static) if (n >= kParallelMinVertices)
  for (Index i = 0; i < n; ++i)
    se_update_vertex(x + 3 * i, v + 3 * i, f + 3 * i, w[i], h, g0, g1, g2);  // se_update.hpp, shared with cuda
}

}  // namespace loom::symplectic_euler
