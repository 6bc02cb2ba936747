// Test-only spring material (Hooke springs with optional axial dampers) that exposes its
// SpringSet, plus helpers to build a small Scene by hand. Shared by tests/harmonic_oscillation,
// tests/rk4 and tests/convergence.
#pragma once

#include <cmath>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "loom/material.hpp"
#include "loom/scene.hpp"
#include "loom/springs.hpp"

namespace loom::testing {

class TestSpringMaterial final : public Material {
 public:
  TestSpringMaterial(SpringSet s, std::vector<double> masses, bool expose_springs = true)
      : s_(std::move(s)), m_(std::move(masses)), expose_(expose_springs) {}
  std::string name() const override { return expose_ ? "test_springs" : "test_no_springs"; }
  void compute_masses(std::span<double> mass) const override {
    for (std::size_t q = 0; q < m_.size(); ++q) mass[q] = m_[q];
  }
  void compute_forces(std::span<const double> x, std::span<const double> v, std::span<double> f) const override {
    ++evaluations;
    for (double& e : f) e = 0;
    for (Index q = 0; q < s_.size(); ++q) {
      const Index a = s_.i[q], b = s_.j[q];
      double d[3], l2 = 0, rel = 0;
      for (int e = 0; e < 3; ++e) {
        d[e] = x[3 * b + e] - x[3 * a + e];
        l2 += d[e] * d[e];
      }
      const double l = std::sqrt(l2);
      for (int e = 0; e < 3; ++e) rel += d[e] / l * (v[3 * b + e] - v[3 * a + e]);
      const double t = s_.stiffness[q] * (l - s_.rest_length[q]) + s_.damping[q] * rel;
      for (int e = 0; e < 3; ++e) {
        f[3 * a + e] += t * d[e] / l;
        f[3 * b + e] -= t * d[e] / l;
      }
    }
  }
  double elastic_energy(std::span<const double> x) const override {
    double E = 0;
    for (Index q = 0; q < s_.size(); ++q) {
      const double dl = length(x, q) - s_.rest_length[q];
      E += 0.5 * s_.stiffness[q] * dl * dl;
    }
    return E;
  }
  double max_strain(std::span<const double> x) const override {
    double m = 0;
    for (Index q = 0; q < s_.size(); ++q)
      m = std::max(m, std::abs(length(x, q) / s_.rest_length[q] - 1));
    return m;
  }
  const SpringSet* springs() const override { return expose_ ? &s_ : nullptr; }

  mutable long evaluations = 0;

 private:
  double length(std::span<const double> x, Index q) const {
    double l2 = 0;
    for (int e = 0; e < 3; ++e) {
      const double d = x[3 * s_.j[q] + e] - x[3 * s_.i[q] + e];
      l2 += d * d;
    }
    return std::sqrt(l2);
  }
  SpringSet s_;
  std::vector<double> m_;
  bool expose_;
};

/// Scene with the given positions (3n), velocities, masses, pins, gravity and material.
inline std::unique_ptr<Scene> make_scene(std::vector<double> x, std::vector<double> v, const std::vector<double>& mass,
                                         const std::vector<Index>& pins, std::array<double, 3> gravity,
                                         std::unique_ptr<Material> mat) {
  auto sc = std::make_unique<Scene>();
  sc->source = "<test>";
  const Index n = static_cast<Index>(mass.size());
  sc->state.resize(n);
  sc->state.x = std::move(x);
  sc->state.v = std::move(v);
  sc->state.mass = mass;
  for (Index p : pins) sc->state.pin(p);
  sc->state.update_inverse_masses();
  sc->gravity = gravity;
  sc->material = std::move(mat);
  return sc;
}

}  // namespace loom::testing
