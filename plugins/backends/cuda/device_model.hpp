// Device-resident pieces of a run: the state, a 3x3 BSR matrix over a fixed pattern, and the
// force model (forces and force Jacobians) built from the material's device description.
//
// The force model never names a concrete material: build() asks the scene's material for its
// DeviceDescription (loom/device_material.hpp, Material::describe_device), blocks of elements
// with the id of the per-element kernel (loom/kernels/) that evaluates them, and sums the blocks:
//   * Spring blocks: two phases, race free without atomics: one thread per spring writes its
//     force / its 3x3 blocks into a per-spring buffer, then one thread per vertex (block row)
//     gathers over its incident springs (a CSR incidence list built once). Deterministic.
//   * GnatvTriangle and Hinge blocks: elements greedily vertex-coloured once: one launch per
//     colour, elements of one colour share no vertex, so each element adds its forces and its
//     arity^2 Jacobian blocks with plain read-modify-writes (a precomputed scatter map into the
//     pattern), no atomics, deterministic. A grid needs 6-8 colours for triangles, ~10 for hinges.
//   * a material without a description (describe_device returns false): the host material is
//     called (x, v copied down, f / Jacobians copied up). Correct, slow; said once on stderr.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "device.hpp"
#include "loom/bsr.hpp"
#include "loom/curves.hpp"
#include "loom/device_material.hpp"
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

enum class ForceModelKind { Device, Host };
const char* to_string(ForceModelKind k);

/// One block of a device description, resident on the device.
template <class T>
struct DeviceSprings {
  Index count = 0;
  bool damped = false, clamp = true;
  DVec<Index> si, sj;
  DVec<T> l0, k, c;
  DVec<Index> inc_ptr, inc_spring, inc_block;
  DVec<signed char> inc_sign;
  DVec<T> per_spring, per_spring_d;
};
template <class T>
struct DeviceColoured {  // GnatvTriangle or Hinge
  ElementKernel kernel = ElementKernel::GnatvTriangle;
  int arity = 3, stride = 7;
  std::uint32_t flags = 0;
  DVec<Index> vert, scatter;  // colour-sorted; scatter: arity^2 per element
  DVec<T> data, shared;
  gnatv::Curves<T> curves{};
  std::vector<Index> colour_start;
};

template <class T>
class DeviceForceModel {
 public:
  /// Read the material's device description. With `pattern` (implicit integrators) also build
  /// the Jacobian scatter maps over it (the material's bind_pattern must already have been
  /// called with the same pattern, for the host fallback).
  /// merge_springs (forces only, pattern null): the springs of a block on the same two vertices
  /// become one (merge_duplicate_springs, loom/springs.hpp: the same force in exact arithmetic),
  /// as the CPU's symplectic_euler and rk4 do (key merge_springs).
  void build(const Scene& scene, const BsrPattern* pattern, bool merge_springs = false);
  ForceModelKind kind() const { return kind_; }
  /// Springs the last build() folded into others (merge_springs).
  Index merged_springs() const { return merged_; }
  /// Kernel ids of the blocks on the device, in evaluation order (tests, messages).
  const std::vector<ElementKernel>& kernels() const { return kernels_; }

  /// f = internal forces at (x, v) (3n device vectors; f overwritten).
  void forces(const DVec<T>& x, const DVec<T>& v, DVec<T>& f);
  /// dfdx (and dfdv when non-null) at x over the pattern given to build().
  void jacobians(const DVec<T>& x, const DVec<T>& v, DVec<T>& dfdx, DVec<T>* dfdv);
  int force_calls() const { return force_calls_; }

 private:
  void add_springs(const ElementBlock& b, const BsrPattern* pattern, bool merge);
  void add_coloured(const ElementBlock& b, const BsrPattern* pattern);

  ForceModelKind kind_ = ForceModelKind::Host;
  Index n_ = 0;
  Index merged_ = 0;
  int force_calls_ = 0;
  const Material* material_ = nullptr;
  std::vector<ElementKernel> kernels_;
  std::vector<std::unique_ptr<DeviceSprings<T>>> springs_;
  std::vector<std::unique_ptr<DeviceColoured<T>>> coloured_;
  DVec<Index> pat_row_ptr_, pat_diag_;
  // host fallback
  std::vector<double> hx_, hv_, hf_;
  std::vector<T> stage_;
  std::unique_ptr<BsrMatrix> hdfdx_, hdfdv_;
  const BsrPattern* pattern_ = nullptr;
};

}  // namespace loom::cuda
