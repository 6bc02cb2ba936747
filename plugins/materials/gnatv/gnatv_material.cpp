#include "gnatv_material.hpp"

#include "loom/colouring.hpp"
#include "loom/device_material.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <stdexcept>

namespace loom::gnatv {

const ParamSpec& gnatv_spec() {
  static const ParamSpec spec = [] {
    const GnatvOptions d;
    ParamSpec s("gnatv", "Volino et al. 2009 triangle material from measured stress-strain curves");
    s.text("material_file", "").required().default_text("required, or fabric: NAME").help(
        "the fabric's curves (YAML; relative to the scene's folder), or give fabric: NAME instead");
    s.choice("interpolation", d.interpolation == CurveInterpolation::BSpline ? "bspline" : "monotone_cubic",
             {"monotone_cubic", "bspline"})
        .help("how the measured stress samples are interpolated");
    s.choice("orientation", "auto", {"auto", "uv", "x_axis"}).help(
        "reference (weft) direction: the mesh's uv, the x axis, or auto (uv when present)");
    s.number("weft_angle", d.weft_angle).range(ParamRange::closed(-2 * std::numbers::pi, 2 * std::numbers::pi))
        .units("rad").help("rotates the weft from the reference direction in the cloth's plane");
    s.number("density", 0).no_default("from the material file").range(ParamRange::positive()).units("kg/m^2").help(
        "areal density (overrides the material file's areal_density)");
    s.number("stress_scale", d.stress_scale).range(ParamRange::positive()).help("multiplies every stress curve");
    s.flag("psd_projection", d.psd_projection).help("project element Jacobians to positive semi-definite");
    return s;
  }();
  return spec;
}

namespace {

using V3 = std::array<double, 3>;
V3 sub(const double* a, const double* b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
V3 cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
V3 scale(const V3& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
V3 axpy(const V3& a, double s, const V3& b) { return {a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]}; }

std::string resolve_against(const std::string& source, const std::string& path) {
  namespace fs = std::filesystem;
  fs::path p(path);
  if (p.is_absolute()) return path;
  fs::path base = fs::path(source).parent_path();
  if (source.empty() || source.front() == '<' || base.empty()) return path;
  return (base / p).lexically_normal().string();
}

GnatvOptions read_options(const Params& params) {
  GnatvOptions o;
  const ParamReader r(params, gnatv_spec());
  const Params& p = r.params();
  const std::string file = r.text("material_file");
  o.material_file = resolve_against(p.source(), file);
  {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(o.material_file, ec))
      p.child("material_file").fail("material file '" + o.material_file + "' " +
                                    (std::filesystem::exists(o.material_file, ec) ? "is not a regular file"
                                                                                  : "does not exist") +
                                    ". Fix: paths are relative to the scene file's folder; measured fabrics are also "
                                    "available by name (fabric: 11oz-black-denim, see materials/wang2011).");
  }
  o.interpolation = r.text("interpolation") == "bspline" ? CurveInterpolation::BSpline
                                                          : CurveInterpolation::MonotoneCubic;
  const std::string orient = r.text("orientation");
  o.orientation = orient == "uv"       ? GnatvOptions::Orientation::UV
                  : orient == "x_axis" ? GnatvOptions::Orientation::XAxis
                                       : GnatvOptions::Orientation::Auto;
  o.weft_angle = r.number("weft_angle");
  o.density = r.has("density") ? r.number("density") : 0.0;
  o.stress_scale = r.number("stress_scale");
  o.psd_projection = r.flag("psd_projection");
  return o;
}

MaterialData read_data(const GnatvOptions& o) {
  return read_material_file(o.material_file, o.interpolation, o.stress_scale);
}

}  // namespace

GnatvMaterial::GnatvMaterial(const Params& p, const Mesh& mesh)
    : GnatvMaterial(read_options(p), MaterialData{}, mesh) {}

GnatvMaterial::GnatvMaterial(const GnatvOptions& opt, MaterialData data, const Mesh& mesh)
    : opt_(opt), data_(std::move(data)) {
  if (data_.weft.size() == 0) data_ = read_data(opt_);
  views_ = {data_.weft.view(), data_.warp.view(), data_.shear.view()};
  density_ = opt_.density > 0 ? opt_.density : data_.areal_density;
  setup(mesh);
}

void GnatvMaterial::setup(const Mesh& mesh) {
  n_ = mesh.num_vertices();
  const Index nt = mesh.num_triangles();
  if (nt == 0) throw InputError("gnatv: mesh " + mesh.source + " has no triangles");
  const bool has_uv = mesh.has_uvs();
  GnatvOptions::Orientation orient = opt_.orientation;
  if (orient == GnatvOptions::Orientation::UV && !has_uv)
    throw InputError("gnatv: orientation: uv needs texture coordinates, but mesh " + mesh.source +
                     " has none; use orientation: x_axis (weft = the x axis projected onto each triangle)");
  if (orient == GnatvOptions::Orientation::Auto)
    orient = has_uv ? GnatvOptions::Orientation::UV : GnatvOptions::Orientation::XAxis;
  const double ca = std::cos(opt_.weft_angle), sa = std::sin(opt_.weft_angle);

  std::vector<RestTriangle<double>> rest(nt);
  for (Index t = 0; t < nt; ++t) {
    const Index* tv = &mesh.triangles[3 * static_cast<std::size_t>(t)];
    for (int k = 0; k < 3; ++k)
      if (tv[k] < 0 || tv[k] >= n_)
        throw InputError("gnatv: triangle " + std::to_string(t) + " of " + mesh.source + " has vertex index " +
                         std::to_string(tv[k]) + " outside 0.." + std::to_string(n_ - 1));
    const double* P0 = &mesh.positions[3 * static_cast<std::size_t>(tv[0])];
    const double* P1 = &mesh.positions[3 * static_cast<std::size_t>(tv[1])];
    const double* P2 = &mesh.positions[3 * static_cast<std::size_t>(tv[2])];
    const V3 ea = sub(P1, P0), eb = sub(P2, P0), ec = sub(P2, P1);
    const V3 nrm = cross(ea, eb);
    const double len2 = std::max({dot(ea, ea), dot(eb, eb), dot(ec, ec)});
    const double nn = std::sqrt(dot(nrm, nrm));
    if (!(nn > 1e-12 * len2) || !std::isfinite(nn))
      throw InputError("gnatv: triangle " + std::to_string(t) + " (vertices " + std::to_string(tv[0]) + ", " +
                       std::to_string(tv[1]) + ", " + std::to_string(tv[2]) + ") of " + mesh.source +
                       " has zero rest area; remove degenerate triangles from the mesh");
    const V3 nh = scale(nrm, 1.0 / nn);
    // Reference weft direction in 3D.
    V3 ref{1.0, 0.0, 0.0};
    if (orient == GnatvOptions::Orientation::UV) {
      // The triangle's own corner uvs (a vertex on a UV seam has another uv in the triangles
      // on the other side).
      const double* w0 = mesh.corner_uv(t, 0);
      const double* w1 = mesh.corner_uv(t, 1);
      const double* w2 = mesh.corner_uv(t, 2);
      const double d1u = w1[0] - w0[0], d1v = w1[1] - w0[1], d2u = w2[0] - w0[0], d2v = w2[1] - w0[1];
      const double det = d1u * d2v - d2u * d1v;
      const double uvlen2 = std::max({d1u * d1u + d1v * d1v, d2u * d2u + d2v * d2v});
      if (!(std::fabs(det) > 1e-12 * uvlen2))
        throw InputError("gnatv: triangle " + std::to_string(t) + " of " + mesh.source +
                         " has degenerate texture coordinates, so its weft direction is undefined; fix the UVs "
                         "or use orientation: x_axis");
      // dP/du = (ea d2v - eb d1v) / det
      ref = scale(axpy(scale(ea, d2v), -d1v, eb), 1.0 / det);
    }
    V3 e1 = axpy(ref, -dot(ref, nh), nh);
    double l1 = std::sqrt(dot(e1, e1));
    if (orient == GnatvOptions::Orientation::XAxis && !(l1 > 1e-6)) {  // triangle normal along x
      ref = {0.0, 1.0, 0.0};
      e1 = axpy(ref, -dot(ref, nh), nh);
      l1 = std::sqrt(dot(e1, e1));
    }
    if (!(l1 > 0))
      throw InputError("gnatv: cannot define the weft direction of triangle " + std::to_string(t));
    e1 = scale(e1, 1.0 / l1);
    const V3 e2 = cross(nh, e1);
    const V3 w1 = axpy(scale(e1, ca), sa, e2);   // weft
    const V3 w2 = axpy(scale(e2, ca), -sa, e1);  // warp
    const double a[2] = {0.0, 0.0};
    const double b[2] = {dot(ea, w1), dot(ea, w2)};
    const double c[2] = {dot(eb, w1), dot(eb, w2)};
    if (!rest_from_2d(a, b, c, rest[t], 0.0))
      throw InputError("gnatv: triangle " + std::to_string(t) + " of " + mesh.source + " has zero rest area");
  }

  // Lumped masses rho s / 3 (NUMERICS.md 2.5).
  mass_.assign(n_, 0.0);
  for (Index t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) mass_[mesh.triangles[3 * t + k]] += density_ * rest[t].area / 3.0;
  for (Index i = 0; i < n_; ++i)
    if (!(mass_[i] > 0))
      throw InputError("gnatv: vertex " + std::to_string(i) + " of " + mesh.source +
                       " belongs to no triangle, so it has no mass; remove unreferenced vertices");

  // Race-free parallel scatter without atomics: triangles are cut into chunks of
  // consecutive mesh triangles (spatially coherent on grids and most meshes) and the
  // chunks are greedily coloured so that two chunks of one colour share no vertex. A
  // thread processes whole chunks, so its writes stay local in memory; colours run one
  // after the other. Storage is sorted by colour, then chunk.
  const Index chunk = std::clamp<Index>((nt + 127) / 128, 8, 256);
  const Index nchunks = (nt + chunk - 1) / chunk;
  const Colouring col = greedy_colouring(nchunks, n_, [&](Index ch, auto&& visit) {  // loom/colouring.hpp
    for (Index t = ch * chunk; t < std::min(nt, (ch + 1) * chunk); ++t)
      for (int k = 0; k < 3; ++k) visit(mesh.triangles[3 * t + k]);
  });
  colour_start_ = col.start;
  const std::vector<Index>& order = col.order;  // chunks sorted by colour (stable)
  chunk_start_.assign(nchunks + 1, 0);
  tri_.resize(nt);
  rest_.resize(nt);
  original_index_.resize(nt);
  Index pos = 0;
  for (Index q = 0; q < nchunks; ++q) {
    const Index ch = order[q];
    chunk_start_[q] = pos;
    for (Index t = ch * chunk; t < std::min(nt, (ch + 1) * chunk); ++t, ++pos) {
      tri_[pos] = {mesh.triangles[3 * t], mesh.triangles[3 * t + 1], mesh.triangles[3 * t + 2]};
      rest_[pos] = rest[t];
      original_index_[pos] = t;
    }
  }
  chunk_start_[nchunks] = pos;
}

void GnatvMaterial::compute_masses(std::span<double> mass) const {
  std::copy(mass_.begin(), mass_.end(), mass.begin());
}

void GnatvMaterial::compute_forces(std::span<const double> x, std::span<const double>, std::span<double> f) const {
  const double* X = x.data();
  double* Fo = f.data();
  const std::size_t n3 = 3 * static_cast<std::size_t>(n_);
  const int ncol = num_colours();
#pragma omp parallel if (n_ >= kParallelMinVertices)  // the one rule (common.hpp)
  {
#pragma omp for schedule(static)
    for (std::size_t i = 0; i < n3; ++i) Fo[i] = 0.0;
    for (int c = 0; c < ncol; ++c) {
#pragma omp for schedule(dynamic, 1)
      for (Index q = colour_start_[c]; q < colour_start_[c + 1]; ++q)
      for (Index t = chunk_start_[q]; t < chunk_start_[q + 1]; ++t) {
        const auto& tv = tri_[t];
        double P[3][3], F[3][3];
        for (int j = 0; j < 3; ++j)
          for (int k = 0; k < 3; ++k) P[j][k] = X[3 * tv[j] + k];
        forces<double, double, false>(rest_[t], views_, P, F);
        for (int j = 0; j < 3; ++j)
          for (int k = 0; k < 3; ++k) Fo[3 * tv[j] + k] += F[j][k];
      }
    }
  }
}

double GnatvMaterial::elastic_energy(std::span<const double> x) const {
  const double* X = x.data();
  const Index nt = num_triangles();
  double E = 0;
#pragma omp parallel for schedule(static) reduction(+ : E) if (n_ >= kParallelMinVertices)
  for (Index t = 0; t < nt; ++t) {
    const auto& tv = tri_[t];
    double P[3][3];
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) P[j][k] = X[3 * tv[j] + k];
    E += energy(rest_[t], views_, P);
  }
  return E;
}

double GnatvMaterial::max_strain(std::span<const double> x) const {
  const double* X = x.data();
  const Index nt = num_triangles();
  double m = 0;
#pragma omp parallel for schedule(static) reduction(max : m) if (n_ >= kParallelMinVertices)
  for (Index t = 0; t < nt; ++t) {
    const auto& tv = tri_[t];
    double P[3][3];
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) P[j][k] = X[3 * tv[j] + k];
    const double s = max_principal_strain(rest_[t], P);
    if (!(s <= m)) m = s;  // NaN propagates as "larger"
  }
  return m;
}

std::vector<std::pair<std::string, std::string>> GnatvMaterial::describe() const {
  auto fmt = [](double v) {
    char b[64];
    std::snprintf(b, sizeof b, "%.6g", v);
    return std::string(b);
  };
  return {{"triangles", std::to_string(num_triangles())},
          {"chunk colours", std::to_string(num_colours())},
          {"chunks", std::to_string(chunk_start_.size() - 1)},
          {"material file", data_.path},
          {"curve measures weft/warp/shear", data_.weft_measure + " / " + data_.warp_measure + " / " + data_.shear_measure},
          {"interpolation", opt_.interpolation == CurveInterpolation::BSpline ? "bspline" : "monotone_cubic"},
          {"areal density (kg/m^2)", fmt(density_)},
          {"weft angle (rad)", fmt(opt_.weft_angle)},
          {"min curve slope weft/warp/shear (N/m)",
           fmt(data_.weft.min_stiffness()) + " / " + fmt(data_.warp.min_stiffness()) + " / " +
               fmt(data_.shear.min_stiffness())},
          {"psd projection", opt_.psd_projection ? "on" : "off"}};
}

void GnatvMaterial::jacobian_pairs(std::vector<std::array<Index, 2>>& pairs) const {
  pairs.reserve(pairs.size() + 3 * tri_.size());
  for (const auto& tv : tri_) {
    pairs.push_back({tv[0], tv[1]});
    pairs.push_back({tv[1], tv[2]});
    pairs.push_back({tv[2], tv[0]});
  }
}

void GnatvMaterial::bind_pattern(const BsrPattern& pattern) {
  if (pattern.n != n_)
    throw std::logic_error("gnatv: Jacobian pattern has " + std::to_string(pattern.n) + " block rows, mesh has " +
                           std::to_string(n_) + " vertices");
  // Storage order is execution order (colour, chunk, triangle), so the first triangle to
  // reach a block can assign it instead of adding: no separate zeroing pass over the
  // matrix. The first write is stored as ~k (negative). Blocks no triangle reaches (when
  // the pattern holds more than jacobian_pairs) are zeroed explicitly.
  scatter_.resize(9 * tri_.size());
  std::vector<char> touched(static_cast<std::size_t>(pattern.nnz_blocks()), 0);
  for (std::size_t t = 0; t < tri_.size(); ++t)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i) {
        const Index k = pattern.find(tri_[t][j], tri_[t][i]);
        if (k < 0)
          throw std::logic_error("gnatv: Jacobian pattern lacks block (" + std::to_string(tri_[t][j]) + ", " +
                                 std::to_string(tri_[t][i]) + "); build it from jacobian_pairs()");
        scatter_[9 * t + 3 * j + i] = touched[k] ? k : ~k;
        touched[k] = 1;
      }
  untouched_.clear();
  for (Index k = 0; k < pattern.nnz_blocks(); ++k)
    if (!touched[k]) untouched_.push_back(k);
  bound_ = &pattern;
}

void GnatvMaterial::compute_jacobians(std::span<const double> x, std::span<const double>, BsrMatrix& dfdx,
                                      BsrMatrix* dfdv) const {
  if (bound_ == nullptr || dfdx.rows() != n_ || dfdx.pattern().nnz_blocks() != bound_->nnz_blocks())
    throw std::logic_error("gnatv: compute_jacobians called before bind_pattern or with another pattern");
  const double* X = x.data();
  double* A = dfdx.values().data();
  const Index* U = untouched_.data();
  const std::size_t nu = untouched_.size();
  double* D = dfdv ? dfdv->values().data() : nullptr;
  const std::size_t nd = dfdv ? dfdv->values().size() : 0;
  const int ncol = num_colours();
  const bool psd = opt_.psd_projection;
#pragma omp parallel if (n_ >= kParallelMinVertices)  // the one rule (common.hpp)
  {
#pragma omp for schedule(static) nowait
    for (std::size_t i = 0; i < nd; ++i) D[i] = 0.0;  // no material damping: df/dv = 0
#pragma omp for schedule(static)
    for (std::size_t q = 0; q < nu; ++q)
      for (int r = 0; r < 9; ++r) A[9 * static_cast<std::size_t>(U[q]) + r] = 0.0;
    for (int c = 0; c < ncol; ++c) {
#pragma omp for schedule(dynamic, 1)
      for (Index q = colour_start_[c]; q < colour_start_[c + 1]; ++q)
      for (Index t = chunk_start_[q]; t < chunk_start_[q + 1]; ++t) {
        const auto& tv = tri_[t];
        double P[3][3], J[3][3][9];
        for (int j = 0; j < 3; ++j)
          for (int k = 0; k < 3; ++k) P[j][k] = X[3 * tv[j] + k];
        jacobian(rest_[t], views_, P, psd, J);
        const Index* sc = &scatter_[9 * static_cast<std::size_t>(t)];
        for (int b = 0; b < 9; ++b) {
          const double* src = J[b / 3][b % 3];
          if (sc[b] < 0) {  // first contribution to this block: assign
            double* dst = A + 9 * static_cast<std::size_t>(~sc[b]);
            for (int e = 0; e < 9; ++e) dst[e] = src[e];
          } else {
            double* dst = A + 9 * static_cast<std::size_t>(sc[b]);
            for (int e = 0; e < 9; ++e) dst[e] += src[e];
          }
        }
      }
    }
  }
}

bool GnatvMaterial::describe_device(DeviceDescription& out) const {
  ElementBlock b;
  b.kernel = ElementKernel::GnatvTriangle;
  b.flags = opt_.psd_projection ? ElementBlock::kPsd : 0u;
  const Index nt = num_triangles();
  b.vertices.resize(3 * static_cast<std::size_t>(nt));
  b.data.resize(7 * static_cast<std::size_t>(nt));
  for (Index t = 0; t < nt; ++t) {
    for (int a = 0; a < 3; ++a) {
      b.vertices[3 * t + a] = tri_[t][a];
      b.data[7 * t + a] = rest_[t].ru[a];
      b.data[7 * t + 3 + a] = rest_[t].rv[a];
    }
    b.data[7 * t + 6] = rest_[t].area;
  }
  b.shared = pack_curves(views_.uu, views_.vv, views_.uv);
  out.blocks.push_back(std::move(b));
  return true;
}

}  // namespace loom::gnatv
