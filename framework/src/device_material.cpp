#include "loom/device_material.hpp"

#include <cmath>
#include <stdexcept>

namespace loom {

const char* to_string(ElementKernel k) {
  switch (k) {
    case ElementKernel::Spring: return "spring";
    case ElementKernel::GnatvTriangle: return "gnatv_triangle";
    case ElementKernel::Hinge: return "hinge";
  }
  return "unknown";
}

int kernel_arity(ElementKernel k) {
  switch (k) {
    case ElementKernel::Spring: return 2;
    case ElementKernel::GnatvTriangle: return 3;
    case ElementKernel::Hinge: return 4;
  }
  return 0;
}

int kernel_stride(ElementKernel k) {
  switch (k) {
    case ElementKernel::Spring: return 3;
    case ElementKernel::GnatvTriangle: return 7;
    case ElementKernel::Hinge: return 2;
  }
  return 0;
}

namespace {

void check_curves(const std::vector<double>& s, const std::string& where) {
  std::size_t off = 0;
  for (int c = 0; c < 3; ++c) {
    if (off + 5 > s.size()) throw std::logic_error(where + ": packed curves are truncated (curve " + std::to_string(c) + ")");
    const double m = s[off];
    if (!(m >= 2) || m != std::floor(m) || m > 1e7)
      throw std::logic_error(where + ": packed curve " + std::to_string(c) + " has an invalid knot count");
    off += 5 + 4 * static_cast<std::size_t>(m);
    if (off > s.size()) throw std::logic_error(where + ": packed curves are truncated (curve " + std::to_string(c) + ")");
  }
  if (off != s.size()) throw std::logic_error(where + ": packed curves have trailing data");
}

}  // namespace

void validate(const DeviceDescription& d, Index n, const std::string& material) {
  for (std::size_t b = 0; b < d.blocks.size(); ++b) {
    const ElementBlock& e = d.blocks[b];
    const std::string where = "material '" + material + "', device block " + std::to_string(b) + " (" +
                              to_string(e.kernel) + ")";
    const int arity = kernel_arity(e.kernel), stride = kernel_stride(e.kernel);
    if (arity == 0) throw std::logic_error(where + ": unknown kernel id " + std::to_string(static_cast<int>(e.kernel)));
    if (e.vertices.size() % static_cast<std::size_t>(arity) != 0)
      throw std::logic_error(where + ": " + std::to_string(e.vertices.size()) + " vertex indices, not a multiple of " +
                             std::to_string(arity));
    const std::size_t m = e.vertices.size() / static_cast<std::size_t>(arity);
    if (e.data.size() != m * static_cast<std::size_t>(stride))
      throw std::logic_error(where + ": " + std::to_string(e.data.size()) + " data values for " + std::to_string(m) +
                             " elements (expected " + std::to_string(stride) + " each)");
    for (Index v : e.vertices)
      if (v < 0 || v >= n)
        throw std::logic_error(where + ": vertex " + std::to_string(v) + " outside 0.." + std::to_string(n - 1));
    for (double x : e.data)
      if (!std::isfinite(x)) throw std::logic_error(where + ": non-finite element data");
    if (e.kernel == ElementKernel::GnatvTriangle) check_curves(e.shared, where);
    else if (!e.shared.empty()) throw std::logic_error(where + ": this kernel takes no shared data");
  }
}

std::vector<double> pack_curves(const CurveView<double>& uu, const CurveView<double>& vv, const CurveView<double>& uv) {
  std::vector<double> out;
  for (const CurveView<double>* c : {&uu, &vv, &uv}) {
    out.insert(out.end(), {static_cast<double>(c->n), c->inv_step, c->left_slope, c->right_slope, c->w_offset});
    out.insert(out.end(), c->x, c->x + c->n);
    out.insert(out.end(), c->y, c->y + c->n);
    out.insert(out.end(), c->m, c->m + c->n);
    out.insert(out.end(), c->cum, c->cum + c->n);
  }
  return out;
}

}  // namespace loom
