// Device-resident pieces of a run: the state, a 3x3 BSR matrix over a fixed pattern, and the
// force model (forces and force Jacobians) read from the scene's CPU material in build().
//
// Force models:
//   * mass_spring: Hooke springs with axial dampers (loom/kernels/spring.hpp). Two phases,
//     race free without atomics: one thread per spring writes its force / its 3x3 blocks into
//     a per-spring buffer, then one thread per vertex (block row) gathers over its incident
//     springs (a CSR incidence list built once). Deterministic.
//   * gnatv: triangles (loom/kernels/gnatv.hpp), greedily vertex-coloured once: one launch
//     per colour, triangles of one colour share no vertex, so each triangle adds its forces and
//     its 9 Jacobian blocks with plain read-modify-writes (a precomputed scatter map into the
//     pattern), no atomics, deterministic. A grid needs 6-8 colours.
//   * any other material: the host material is called (x, v copied down, f / Jacobians copied
//     up). Correct, slow; the module says so once on stderr.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "device.hpp"
#include "loom/bsr.hpp"
#include "loom/curves.hpp"
#include "loom/kernels/gnatv.hpp"
#include "loom/material.hpp"
#include "loom/scene.hpp"
#include "loom/state.hpp"

namespace loom::cuda {

/// Positions, velocities (3n) and inverse masses, masses (n) on the device.
template <class T>
struct DeviceState {
  Index n = 0;
  DVec<T> x, v, w, mass;
  std::vector<T> stage;  // host staging for float downloads

  void upload(const State& s) {
    n = s.size();
    cuda::upload(s.x, x);
    cuda::upload(s.v, v);
    cuda::upload(s.inv_mass, w);
    cuda::upload(s.mass, mass);
  }
  /// Positions and velocities back into the host state.
  void download(State& s) {
    cuda::download(x, s.x, stage);
    cuda::download(v, s.v, stage);
  }
};

/// 3x3 block-sparse matrix on the device over a pattern built once on the host.
template <class T>
struct DeviceBsr {
  Index n = 0, nnzb = 0;
  DVec<Index> row_ptr, col, diag;
  DVec<T> values;

  void set_pattern(const BsrPattern& p) {
    n = p.n;
    nnzb = p.nnz_blocks();
    cuda::upload(p.row_ptr, row_ptr);
    cuda::upload(p.col, col);
    cuda::upload(p.diag, diag);
    values.assign(9 * static_cast<std::size_t>(nnzb), T(0));
  }
  /// y = A x through the seam (cuSPARSE or the Thrust stand-in).
  void multiply(const T* x, T* y) const { seam_bsr_spmv(n, nnzb, raw(row_ptr), raw(col), raw(values), x, y); }
};

enum class ForceModelKind { Springs, Gnatv, Host };
const char* to_string(ForceModelKind k);

template <class T>
class DeviceForceModel {
 public:
  /// Read the material's description. With `pattern` (implicit integrators) also build the
  /// Jacobian scatter maps over it (the material's bind_pattern must already have been called
  /// with the same pattern, for the host fallback).
  void build(const Scene& scene, const BsrPattern* pattern);
  ForceModelKind kind() const { return kind_; }

  /// f = internal forces at (x, v) (3n device vectors; f overwritten).
  void forces(const DVec<T>& x, const DVec<T>& v, DVec<T>& f);
  /// dfdx (and dfdv when non-null) at x over the pattern given to build().
  void jacobians(const DVec<T>& x, const DVec<T>& v, DVec<T>& dfdx, DVec<T>* dfdv);
  int force_calls() const { return force_calls_; }

 private:
  ForceModelKind kind_ = ForceModelKind::Host;
  Index n_ = 0;
  int force_calls_ = 0;
  const Material* material_ = nullptr;
  // springs
  DVec<Index> si_, sj_;
  DVec<T> l0_, k_, c_;
  bool damped_ = false, clamp_ = true;
  DVec<Index> inc_ptr_, inc_spring_, inc_block_, pat_row_ptr_, pat_diag_;
  DVec<signed char> inc_sign_;
  DVec<T> per_spring_, per_spring_d_;
  // gnatv
  DVec<Index> tri_, tri_scatter_;
  DVec<gnatv::RestTriangle<T>> rest_;
  DVec<T> curve_data_;
  gnatv::Curves<T> curves_{};
  std::vector<Index> colour_start_;
  bool psd_ = true;
  // host fallback
  std::vector<double> hx_, hv_, hf_;
  std::vector<T> stage_;
  std::unique_ptr<BsrMatrix> hdfdx_, hdfdv_;
  const BsrPattern* pattern_ = nullptr;
};

}  // namespace loom::cuda
