#include "loom/bending.hpp"

#include "loom/colouring.hpp"
#include "loom/device_material.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <numbers>
#include <stdexcept>

namespace loom {

namespace {

std::string fmt(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

}  // namespace

BendingOptions read_bending_options(const Params& p) {
  if (!p.is_map())
    p.fail("must be a mapping like {stiffness: 1.0e-5} (bending rigidity in N m) or "
           "{stiffness: {weft: 2.0e-5, warp: 1.0e-5, bias: 1.5e-5}}.");
  BendingOptions o;
  Params s = p.child("stiffness");
  if (!s.valid()) p.fail("missing key 'stiffness' (bending rigidity B in N m, e.g. stiffness: 1.0e-5).");
  if (s.is_map()) {
    for (const char* k : {"weft", "warp", "bias"}) s.mark_used(k);
    if (!s.has("weft") || !s.has("warp"))
      s.fail("an anisotropic stiffness needs 'weft' and 'warp' (and optionally 'bias'), in N m.");
    o.b_weft = s.get_nonnegative("weft", 0.0);
    o.b_warp = s.get_nonnegative("warp", 0.0);
    o.b_bias = s.has("bias") ? s.get_nonnegative("bias", 0.0) : 0.5 * (o.b_weft + o.b_warp);
    s.check_unused();
    o.anisotropic = !(o.b_weft == o.b_warp && o.b_bias == o.b_weft);
  } else {
    o.b_weft = o.b_warp = o.b_bias = p.get_nonnegative("stiffness", 0.0);
  }
  const std::string jac = p.get_choice("jacobian", "gauss_newton", {"gauss_newton", "exact"});
  o.exact_jacobian = jac == "exact";
  o.skip_non_manifold = p.get_choice("non_manifold", "error", {"error", "skip"}) == "skip";
  o.weft_angle = p.get_in_range("weft_angle", 0.0, -2 * std::numbers::pi, 2 * std::numbers::pi);
  p.check_unused();
  return o;
}

HingeSet::HingeSet(const Mesh& mesh, const BendingOptions& opt) : opt_(opt) {
  n_ = mesh.num_vertices();
  const Index nt = mesh.num_triangles();
  const bool has_uv = mesh.has_uvs();
  if (opt_.anisotropic && !has_uv)
    throw InputError("bending: anisotropic stiffness (weft != warp) needs texture coordinates to find each edge's "
                     "direction, but mesh " + mesh.source +
                     " has none. Fix: add vt coordinates to the OBJ, or give one isotropic stiffness.");
  // Directed half-edges (lower, upper, opposite vertex), sorted: equal keys share an edge. Each
  // keeps its triangle and the corners (0..2) of i and j in it, for the edge's texture direction.
  struct Half {
    Index i, j, opp, t;
    int ci, cj;
  };
  std::vector<Half> half;
  half.reserve(3 * static_cast<std::size_t>(nt));
  for (Index t = 0; t < nt; ++t) {
    const Index* tv = &mesh.triangles[3 * static_cast<std::size_t>(t)];
    for (int k = 0; k < 3; ++k) {
      const Index a = tv[k], b = tv[(k + 1) % 3], c = tv[(k + 2) % 3];
      if (a < b) half.push_back({a, b, c, t, k, (k + 1) % 3});
      else half.push_back({b, a, c, t, (k + 1) % 3, k});
    }
  }
  std::sort(half.begin(), half.end(), [](const Half& x, const Half& y) {
    return x.i != y.i ? x.i < y.i : (x.j != y.j ? x.j < y.j : (x.opp != y.opp ? x.opp < y.opp : x.t < y.t));
  });
  std::vector<std::array<Index, 4>> hinges;
  // Per hinge: the half-edge of its first triangle (the one with the lower opposite vertex),
  // whose corner uvs give the edge's direction in texture space.
  std::vector<Half> hinge_half;
  std::vector<std::string> bad;
  std::size_t nbad = 0;
  for (std::size_t s = 0; s < half.size();) {
    std::size_t e = s + 1;
    while (e < half.size() && half[e].i == half[s].i && half[e].j == half[s].j) ++e;
    const std::size_t m = e - s;
    if (m == 2) {
      hinges.push_back({half[s].i, half[s].j, half[s].opp, half[s + 1].opp});
      hinge_half.push_back(half[s]);
    } else if (m > 2) {
      ++nbad;
      if (bad.size() < 10)
        bad.push_back("edge (" + std::to_string(half[s].i) + ", " + std::to_string(half[s].j) + ") shared by " +
                      std::to_string(m) + " triangles");
    }
    s = e;
  }
  if (nbad > 0) {
    std::string list;
    for (const auto& b : bad) list += (list.empty() ? "" : "; ") + b;
    if (nbad > bad.size()) list += "; and " + std::to_string(nbad - bad.size()) + " more";
    if (!opt_.skip_non_manifold)
      throw InputError("bending: mesh " + mesh.source + " has " + std::to_string(nbad) +
                       " non-manifold edge(s), where a dihedral angle is undefined: " + list +
                       ". Fix: split the mesh there, or set bending: {non_manifold: skip} to leave those edges "
                       "without bending.");
    warnings_.push_back("bending: skipping " + std::to_string(nbad) + " non-manifold edge(s) of " + mesh.source +
                        " (no bending across them): " + list);
  }

  // Rest data: k = B(edge angle) |e|^2 / (2 (A0 + A1)), theta0 from the mesh.
  const double* P = mesh.positions.data();
  const Index nh = static_cast<Index>(hinges.size());
  std::vector<bending::RestHinge<double>> rest(nh);
  for (Index h = 0; h < nh; ++h) {
    const auto& v = hinges[h];
    double X[4][3], g[4][3], theta;
    for (int a = 0; a < 4; ++a)
      for (int k = 0; k < 3; ++k) X[a][k] = P[3 * static_cast<std::size_t>(v[a]) + k];
    if (!bending::angle_gradient(X, theta, g))
      throw InputError("bending: the hinge at edge (" + std::to_string(v[0]) + ", " + std::to_string(v[1]) + ") of " +
                       mesh.source + " has a collapsed triangle, so its rest angle is undefined. Fix: remove "
                       "degenerate triangles from the mesh.");
    double e[3], a[3], b[3], nA[3], nB[3];
    for (int k = 0; k < 3; ++k) {
      e[k] = X[1][k] - X[0][k];
      a[k] = X[2][k] - X[0][k];
      b[k] = X[3][k] - X[0][k];
    }
    bending::hinge_cross(e, a, nA);
    bending::hinge_cross(b, e, nB);
    const double area2 = std::sqrt(bending::hinge_dot(nA, nA)) + std::sqrt(bending::hinge_dot(nB, nB));  // 2 (A0 + A1)
    double B = opt_.b_weft;
    if (opt_.anisotropic) {
      // The edge's two corners in the hinge's first triangle (opposite vertex v[2]). Across a
      // UV seam the other triangle's corners differ by a translation (the same direction) or a
      // turn by pi (the opposite one); stiffness_at_edge_angle folds the angle into [0, pi/2],
      // so either triangle gives the same B there (a mirror u -> -u too when weft_angle is 0).
      const Half& hh = hinge_half[h];
      const double* w0 = mesh.corner_uv(hh.t, hh.ci);
      const double* w1 = mesh.corner_uv(hh.t, hh.cj);
      const double du = w1[0] - w0[0], dv = w1[1] - w0[1];
      if (!(du * du + dv * dv > 0))
        throw InputError("bending: edge (" + std::to_string(v[0]) + ", " + std::to_string(v[1]) + ") of " +
                         mesh.source + " has zero length in texture space, so its direction relative to the weft "
                         "is undefined. Fix the texture coordinates.");
      const double phi = std::atan2(dv, du) - opt_.weft_angle;
      B = bending::stiffness_at_edge_angle(phi, opt_.b_warp, opt_.b_bias, opt_.b_weft);
    }
    rest[h].k = B * bending::hinge_dot(e, e) / area2;  // B |e|^2 / (2 (A0 + A1))
    rest[h].theta0 = theta;
  }

  // Greedy vertex colouring (loom/colouring.hpp): hinges of one colour share no vertex.
  const Colouring col = greedy_colouring(nh, n_, [&](Index h, auto&& visit) {
    for (int a = 0; a < 4; ++a) visit(hinges[h][a]);
  });
  colour_start_ = col.start;
  hinge_.resize(nh);
  rest_.resize(nh);
  for (Index q = 0; q < nh; ++q) {
    hinge_[q] = hinges[col.order[q]];
    rest_[q] = rest[col.order[q]];
  }
}

void HingeSet::add_forces(std::span<const double> x, std::span<double> f) const {
  const double* X = x.data();
  double* Fo = f.data();
  const int ncol = num_colours();
#pragma omp parallel if (n_ >= kParallelMinVertices)
  for (int c = 0; c < ncol; ++c) {
#pragma omp for schedule(static)
    for (Index h = colour_start_[c]; h < colour_start_[c + 1]; ++h) {
      const auto& v = hinge_[h];
      double P[4][3], F[4][3];
      for (int a = 0; a < 4; ++a)
        for (int k = 0; k < 3; ++k) P[a][k] = X[3 * static_cast<std::size_t>(v[a]) + k];
      bending::forces(rest_[h], P, F);
      for (int a = 0; a < 4; ++a)
        for (int k = 0; k < 3; ++k) Fo[3 * static_cast<std::size_t>(v[a]) + k] += F[a][k];
    }
  }
}

double HingeSet::energy(std::span<const double> x) const {
  const double* X = x.data();
  const Index nh = num_hinges();
  double E = 0;
#pragma omp parallel for schedule(static) reduction(+ : E) if (n_ >= kParallelMinVertices)
  for (Index h = 0; h < nh; ++h) {
    const auto& v = hinge_[h];
    double P[4][3];
    for (int a = 0; a < 4; ++a)
      for (int k = 0; k < 3; ++k) P[a][k] = X[3 * static_cast<std::size_t>(v[a]) + k];
    E += bending::energy(rest_[h], P);
  }
  return E;
}

void HingeSet::jacobian_pairs(std::vector<std::array<Index, 2>>& pairs) const {
  pairs.reserve(pairs.size() + 6 * hinge_.size());
  for (const auto& v : hinge_)
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) pairs.push_back({v[a], v[b]});
}

void HingeSet::bind_pattern(const BsrPattern& pattern) {
  if (pattern.n != n_)
    throw std::logic_error("bending: Jacobian pattern has " + std::to_string(pattern.n) + " block rows, mesh has " +
                           std::to_string(n_) + " vertices");
  scatter_.resize(16 * hinge_.size());
  for (std::size_t h = 0; h < hinge_.size(); ++h)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        const Index k = pattern.find(hinge_[h][a], hinge_[h][b]);
        if (k < 0)
          throw std::logic_error("bending: Jacobian pattern lacks block (" + std::to_string(hinge_[h][a]) + ", " +
                                 std::to_string(hinge_[h][b]) + "); build it from jacobian_pairs()");
        scatter_[16 * h + 4 * a + b] = k;
      }
  bound_ = &pattern;
}

void HingeSet::add_jacobian(std::span<const double> x, BsrMatrix& dfdx) const {
  if (bound_ == nullptr || dfdx.rows() != n_ || dfdx.pattern().nnz_blocks() != bound_->nnz_blocks())
    throw std::logic_error("bending: add_jacobian called before bind_pattern or with another pattern");
  const double* X = x.data();
  double* A = dfdx.values().data();
  const int ncol = num_colours();
  const bool exact = opt_.exact_jacobian;
#pragma omp parallel if (n_ >= kParallelMinVertices)
  for (int c = 0; c < ncol; ++c) {
#pragma omp for schedule(static)
    for (Index h = colour_start_[c]; h < colour_start_[c + 1]; ++h) {
      const auto& v = hinge_[h];
      double P[4][3], J[4][4][9];
      for (int a = 0; a < 4; ++a)
        for (int k = 0; k < 3; ++k) P[a][k] = X[3 * static_cast<std::size_t>(v[a]) + k];
      bending::jacobian(rest_[h], P, exact, J);
      const Index* sc = &scatter_[16 * static_cast<std::size_t>(h)];
      for (int b = 0; b < 16; ++b) {
        double* dst = A + 9 * static_cast<std::size_t>(sc[b]);
        const double* src = J[b / 4][b % 4];
        for (int e = 0; e < 9; ++e) dst[e] += src[e];
      }
    }
  }
}

BentMaterial::BentMaterial(std::unique_ptr<Material> membrane, const Mesh& mesh, const BendingOptions& opt)
    : membrane_(std::move(membrane)), hinges_(mesh, opt) {}

void BentMaterial::compute_forces(std::span<const double> x, std::span<const double> v, std::span<double> f) const {
  membrane_->compute_forces(x, v, f);
  hinges_.add_forces(x, f);
}

double BentMaterial::elastic_energy(std::span<const double> x) const {
  return membrane_->elastic_energy(x) + hinges_.energy(x);
}

std::vector<std::pair<std::string, std::string>> BentMaterial::describe() const {
  auto d = membrane_->describe();
  const auto& o = hinges_.options();
  d.push_back({"bending hinges", std::to_string(hinges_.num_hinges())});
  d.push_back({"bending B weft/warp/bias (N m)", fmt(o.b_weft) + " / " + fmt(o.b_warp) + " / " + fmt(o.b_bias)});
  d.push_back({"bending jacobian", o.exact_jacobian ? "exact" : "gauss_newton"});
  return d;
}

bool BentMaterial::describe_device(DeviceDescription& out) const {
  DeviceDescription d;
  if (!membrane_->describe_device(d)) return false;
  ElementBlock b;
  b.kernel = ElementKernel::Hinge;
  b.flags = hinges_.options().exact_jacobian ? ElementBlock::kExactJacobian : 0u;
  const Index nh = hinges_.num_hinges();
  b.vertices.resize(4 * static_cast<std::size_t>(nh));
  b.data.resize(2 * static_cast<std::size_t>(nh));
  for (Index h = 0; h < nh; ++h) {
    for (int a = 0; a < 4; ++a) b.vertices[4 * h + a] = hinges_.hinges()[h][a];
    b.data[2 * h] = hinges_.rest()[h].k;
    b.data[2 * h + 1] = hinges_.rest()[h].theta0;
  }
  d.blocks.push_back(std::move(b));
  for (auto& blk : d.blocks) out.blocks.push_back(std::move(blk));
  return true;
}

void BentMaterial::jacobian_pairs(std::vector<std::array<Index, 2>>& pairs) const {
  membrane_->jacobian_pairs(pairs);
  hinges_.jacobian_pairs(pairs);
}

void BentMaterial::bind_pattern(const BsrPattern& pattern) {
  membrane_->bind_pattern(pattern);
  hinges_.bind_pattern(pattern);
}

void BentMaterial::compute_jacobians(std::span<const double> x, std::span<const double> v, BsrMatrix& dfdx,
                                     BsrMatrix* dfdv) const {
  membrane_->compute_jacobians(x, v, dfdx, dfdv);  // overwrites every value of the pattern
  hinges_.add_jacobian(x, dfdx);                   // no bending damping: dfdv unchanged
}

std::unique_ptr<Material> add_bending(std::unique_ptr<Material> material, const Params& bending, const Mesh& mesh,
                                      const std::string& backend) {
  if (!bending.valid()) return material;
  if (backend != "cpu" && backend != "cuda")  // cuda: the Hinge block of describe_device()
    bending.fail("bending is not supported on backend '" + backend +
                 "' (it has no hinge kernel). Fix: set backend: cpu or cuda, or remove the bending block.");
  const BendingOptions opt = read_bending_options(bending);
  auto m = std::make_unique<BentMaterial>(std::move(material), mesh, opt);
  for (const auto& w : m->hinges().warnings()) std::cerr << "loom: warning: " << w << "\n";
  return m;
}

}  // namespace loom
