// Test-only materials with exact Jacobians, for the Baraff-Witkin tests: zero forces
// (free fall, damping recurrences) and a small Hookean spring network with the
// compressed-spring clamp switchable (NUMERICS.md 3.5). Serial and simple on purpose.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <span>
#include <string>
#include <vector>

#include "loom/bsr.hpp"
#include "loom/material.hpp"
#include "loom/mesh.hpp"
#include "loom/scene.hpp"
#include "loom/state.hpp"

namespace loom::testing {

/// No internal forces; the Jacobian pattern couples the given pairs (so the Kang-Cho
/// Laplacian has neighbours) but all Jacobian values are zero.
class NullMaterial : public Material {
 public:
  NullMaterial(std::vector<double> masses, std::vector<std::array<Index, 2>> pairs)
      : masses_(std::move(masses)), pairs_(std::move(pairs)) {}
  std::string name() const override { return "test_null"; }
  void compute_masses(std::span<double> m) const override { std::copy(masses_.begin(), masses_.end(), m.begin()); }
  void compute_forces(std::span<const double>, std::span<const double>, std::span<double> f) const override {
    std::fill(f.begin(), f.end(), 0.0);
  }
  double elastic_energy(std::span<const double>) const override { return 0; }
  double max_strain(std::span<const double>) const override { return 0; }
  bool has_jacobian() const override { return true; }
  void jacobian_pairs(std::vector<std::array<Index, 2>>& p) const override { p = pairs_; }
  void compute_jacobians(std::span<const double>, std::span<const double>, BsrMatrix& dfdx,
                         BsrMatrix* dfdv) const override {
    std::fill(dfdx.values().begin(), dfdx.values().end(), 0.0);
    if (dfdv) std::fill(dfdv->values().begin(), dfdv->values().end(), 0.0);
  }

 private:
  std::vector<double> masses_;
  std::vector<std::array<Index, 2>> pairs_;
};

/// Hookean springs f_i = k (l - l0) n, n = (x_j - x_i)/l, with the exact Jacobian
/// df_i/dx_j = k [n n^T + (1 - l0/l)(I - n n^T)] (transverse term clamped at 0 when clamp).
class SpringMaterial : public Material {
 public:
  struct Spring {
    Index i, j;
    double l0, k;
  };
  SpringMaterial(std::vector<double> masses, std::vector<Spring> springs, bool clamp)
      : masses_(std::move(masses)), springs_(std::move(springs)), clamp_(clamp) {}
  std::string name() const override { return "test_springs"; }
  void compute_masses(std::span<double> m) const override { std::copy(masses_.begin(), masses_.end(), m.begin()); }
  void compute_forces(std::span<const double> x, std::span<const double>, std::span<double> f) const override {
    std::fill(f.begin(), f.end(), 0.0);
    for (const Spring& s : springs_) {
      double d[3], l = 0;
      for (int c = 0; c < 3; ++c) {
        d[c] = x[3 * s.j + c] - x[3 * s.i + c];
        l += d[c] * d[c];
      }
      l = std::sqrt(l);
      const double fm = s.k * (l - s.l0) / l;
      for (int c = 0; c < 3; ++c) {
        f[3 * s.i + c] += fm * d[c];
        f[3 * s.j + c] -= fm * d[c];
      }
    }
  }
  double elastic_energy(std::span<const double> x) const override {
    double e = 0;
    for (const Spring& s : springs_) {
      const double l = length(x, s);
      e += 0.5 * s.k * (l - s.l0) * (l - s.l0);
    }
    return e;
  }
  double max_strain(std::span<const double> x) const override {
    double m = 0;
    for (const Spring& s : springs_) m = std::max(m, std::abs(length(x, s) / s.l0 - 1.0));
    return m;
  }
  bool has_jacobian() const override { return true; }
  void jacobian_pairs(std::vector<std::array<Index, 2>>& p) const override {
    p.clear();
    for (const Spring& s : springs_) p.push_back({s.i, s.j});
  }
  void bind_pattern(const BsrPattern& P) override {
    slots_.clear();
    for (const Spring& s : springs_)
      slots_.push_back({P.find(s.i, s.i), P.find(s.i, s.j), P.find(s.j, s.i), P.find(s.j, s.j)});
  }
  void compute_jacobians(std::span<const double> x, std::span<const double>, BsrMatrix& dfdx,
                         BsrMatrix* dfdv) const override {
    std::fill(dfdx.values().begin(), dfdx.values().end(), 0.0);
    if (dfdv) std::fill(dfdv->values().begin(), dfdv->values().end(), 0.0);
    for (std::size_t e = 0; e < springs_.size(); ++e) {
      const Spring& s = springs_[e];
      double d[3], l = 0;
      for (int c = 0; c < 3; ++c) {
        d[c] = x[3 * s.j + c] - x[3 * s.i + c];
        l += d[c] * d[c];
      }
      l = std::sqrt(l);
      double t = 1.0 - s.l0 / l;
      if (clamp_) t = std::max(0.0, t);
      double K[9];
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) {
          const double nn = d[a] * d[b] / (l * l);
          K[3 * a + b] = s.k * (nn + t * ((a == b ? 1.0 : 0.0) - nn));
        }
      const auto& sl = slots_[e];
      for (int q = 0; q < 9; ++q) {
        dfdx.block(sl[0])[q] -= K[q];
        dfdx.block(sl[1])[q] += K[q];
        dfdx.block(sl[2])[q] += K[q];
        dfdx.block(sl[3])[q] -= K[q];
      }
    }
  }

 private:
  static double length(std::span<const double> x, const Spring& s) {
    double l = 0;
    for (int c = 0; c < 3; ++c) {
      const double d = x[3 * s.j + c] - x[3 * s.i + c];
      l += d * d;
    }
    return std::sqrt(l);
  }
  std::vector<double> masses_;
  std::vector<Spring> springs_;
  bool clamp_;
  std::vector<std::array<Index, 4>> slots_;
};

/// Structural + shear springs of an nx x ny grid with spacing dx in the plane given by
/// the rest positions (vertex iy * nx + ix).
inline std::vector<SpringMaterial::Spring> grid_springs(Index nx, Index ny, double dx, double k) {
  std::vector<SpringMaterial::Spring> s;
  const double diag = dx * std::sqrt(2.0);
  for (Index iy = 0; iy < ny; ++iy)
    for (Index ix = 0; ix < nx; ++ix) {
      const Index v = iy * nx + ix;
      if (ix + 1 < nx) s.push_back({v, v + 1, dx, k});
      if (iy + 1 < ny) s.push_back({v, v + nx, dx, k});
      if (ix + 1 < nx && iy + 1 < ny) {
        s.push_back({v, v + nx + 1, diag, k});
        s.push_back({v + 1, v + nx, diag, k});
      }
    }
  return s;
}

/// A scene holding only a state and a material (no mesh file, no plugins loaded).
inline void init_scene(Scene& sc, std::span<const double> x0, std::unique_ptr<Material> mat) {
  const Index n = static_cast<Index>(x0.size() / 3);
  sc.state.resize(n);
  std::copy(x0.begin(), x0.end(), sc.state.x.begin());
  std::fill(sc.state.v.begin(), sc.state.v.end(), 0.0);
  mat->compute_masses(sc.state.mass);
  sc.state.update_inverse_masses();
  sc.material = std::move(mat);
}

}  // namespace loom::testing
