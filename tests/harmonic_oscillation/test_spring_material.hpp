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

/// An nx x nx sheet (spacing 0.02, slightly rippled, varied velocities and masses) with
/// structural springs (one direction damped, written with either endpoint first), shear springs
/// and, when `bend`, bend springs two apart: the cloth of the fused-path tests (SE, RK4).
struct TestCloth {
  std::vector<double> x, v, m;
  SpringSet springs;
};
inline TestCloth make_test_cloth(int nx, bool bend) {
  TestCloth t;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      t.x.insert(t.x.end(), {0.02 * c, 0.001 * std::sin(0.7 * c + r), 0.02 * r});
      t.v.insert(t.v.end(), {0.01 * std::sin(r + 2.0 * c), 0.02 * std::cos(3.0 * r - c), 0.0});
      t.m.push_back(1e-3 * (1 + 0.5 * ((r * 7 + c * 3) % 5)));
    }
  SpringSet& s = t.springs;
  for (int r = 0; r < nx; ++r)
    for (int c = 0; c < nx; ++c) {
      const int a = r * nx + c;
      if (c + 1 < nx) s.add(a + 1, a, 0.02, 2000, 0.02, SpringClass::Structural);   // either endpoint first
      if (r + 1 < nx) s.add(a, a + nx, 0.02, 2000, 0.0, SpringClass::Structural);
      if (c + 1 < nx && r + 1 < nx) s.add(a, a + nx + 1, 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
      if (c > 0 && r + 1 < nx) s.add(a, a + nx - 1, 0.02 * std::sqrt(2.0), 500, 0.0, SpringClass::Shear);
      if (bend && c + 2 < nx) s.add(a, a + 2, 0.04, 50, 0.0, SpringClass::Bend);
    }
  return t;
}

}  // namespace loom::testing
