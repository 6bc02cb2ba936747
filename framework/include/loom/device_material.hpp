// The device-ready description of a material: the boundary between materials and execution
// backends that run per-element kernels themselves (the CUDA backend).
//
// A material that wants to run on such a backend exports, once at set-up, its elements as
// plain arrays plus the id of the per-element kernel that evaluates them:
//
//     bool Material::describe_device(DeviceDescription& out) const
//
// The kernels are the host+device headers under loom/kernels/ that the CPU materials use
// themselves, so a backend evaluates exactly the CPU math. The backend knows kernel ids, never
// a concrete material: a new material (in tree or out of tree) runs on the device without an
// edit in the backend as long as its elements are sums of known kernels. Blocks are summed:
// forces, force Jacobians (df/dx) and damping Jacobians (df/dv) of all blocks add up. A
// material with no description (returns false) is evaluated on the host by the backend.
//
// Per kernel (arity = vertices per element, stride = doubles of `data` per element):
//   Spring         kernels/spring.hpp. arity 2 (i, j), stride 3 {rest_length, stiffness,
//                  damping}; flag kClampCompressed (no transverse stiffness when compressed).
//   GnatvTriangle  kernels/gnatv.hpp. arity 3, stride 7 {ru0, ru1, ru2, rv0, rv1, rv2, area};
//                  shared = the three curves uu, vv, uv packed by pack_curves(); flag kPsd
//                  (PSD projection of the Jacobian). No damping.
//   Hinge          kernels/bending.hpp. arity 4 (x0, x1 the edge; x2, x3 opposite), stride 2
//                  {k, theta0}; flag kExactJacobian (else the Gauss-Newton term). No damping.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "loom/common.hpp"
#include "loom/curves.hpp"

namespace loom {

enum class ElementKernel : std::int32_t { Spring = 1, GnatvTriangle = 2, Hinge = 3 };

/// Name of a kernel id, for messages ("spring", "gnatv_triangle", "hinge").
const char* to_string(ElementKernel k);
/// Vertices per element and doubles of per-element data of a kernel.
int kernel_arity(ElementKernel k);
int kernel_stride(ElementKernel k);

/// One kind of element: `vertices` holds kernel_arity() indices per element, `data`
/// kernel_stride() doubles per element, `shared` data common to all of them.
struct ElementBlock {
  ElementKernel kernel = ElementKernel::Spring;
  std::vector<Index> vertices;
  std::vector<double> data;
  std::vector<double> shared;
  std::uint32_t flags = 0;

  static constexpr std::uint32_t kClampCompressed = 1u;  ///< Spring
  static constexpr std::uint32_t kPsd = 2u;              ///< GnatvTriangle
  static constexpr std::uint32_t kExactJacobian = 4u;    ///< Hinge

  Index size() const { return static_cast<Index>(vertices.size() / static_cast<std::size_t>(kernel_arity(kernel))); }
};

/// Everything a backend needs to evaluate a material's internal forces and Jacobians.
struct DeviceDescription {
  std::vector<ElementBlock> blocks;
};

/// Throws std::logic_error naming `material` when a block is inconsistent (sizes that do not
/// match the kernel, vertices outside 0..n-1, non-finite data, malformed shared data).
void validate(const DeviceDescription& d, Index n, const std::string& material);

/// GnatvTriangle shared data: per curve (uu, vv, uv) the header {n, inv_step, left_slope,
/// right_slope, w_offset} followed by x[n], y[n], m[n], cum[n].
std::vector<double> pack_curves(const CurveView<double>& uu, const CurveView<double>& vv, const CurveView<double>& uv);

/// Views of packed curves whose arrays live at `base` (a copy of `packed` in the scalar type
/// R, e.g. on a device); header values are read from `packed` (host memory).
template <class R>
void unpack_curves(const std::vector<double>& packed, const R* base, CurveView<R> out[3]) {
  std::size_t off = 0;
  for (int c = 0; c < 3; ++c) {
    const int m = static_cast<int>(packed[off]);
    out[c].n = m;
    out[c].inv_step = static_cast<R>(packed[off + 1]);
    out[c].left_slope = static_cast<R>(packed[off + 2]);
    out[c].right_slope = static_cast<R>(packed[off + 3]);
    out[c].w_offset = static_cast<R>(packed[off + 4]);
    const R* a = base + off + 5;
    out[c].x = a;
    out[c].y = a + m;
    out[c].m = a + 2 * m;
    out[c].cum = a + 3 * m;
    off += 5 + 4 * static_cast<std::size_t>(m);
  }
}

}  // namespace loom
