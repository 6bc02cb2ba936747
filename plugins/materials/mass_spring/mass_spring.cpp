#include "mass_spring.hpp"

#include <algorithm>
#include <cstdint>
#include <cmath>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <tuple>

#include "loom/device_material.hpp"
#include "loom/kernels/spring.hpp"

namespace loom::mass_spring {

const char* to_string(Stencil s) {
  switch (s) {
    case Stencil::MeshEdges: return "mesh_edges";
    case Stencil::StructuralShearBend: return "structural_shear_bend";
    case Stencil::RadiusSqrt5: return "radius_sqrt5";
    case Stencil::KangChoTable1: return "kang_cho_table1";
  }
  return "?";
}

bool parse_stencil(const std::string& name, Stencil& out) {
  for (Stencil s : {Stencil::MeshEdges, Stencil::StructuralShearBend, Stencil::RadiusSqrt5,
                    Stencil::KangChoTable1}) {
    if (name == to_string(s)) {
      out = s;
      return true;
    }
  }
  return false;
}

namespace {

struct Offset {
  int dx, dy;
  SpringClass cls;
};

class Builder {
 public:
  Builder(const Mesh& mesh, const ClassValues& k, const ClassValues& c) : mesh_(mesh), k_(k), c_(c) {}
  void add(Index a, Index b, SpringClass cls) {
    if (a > b) std::swap(a, b);
    const double* p = mesh_.positions.data();
    const double l0 = kernels::spring_length(p + 3 * a, p + 3 * b);
    raw_.push_back({a, b, cls, l0});
  }
  void add_offsets(const GridInfo& g, std::initializer_list<Offset> offsets) {
    for (Index iy = 0; iy < g.ny; ++iy)
      for (Index ix = 0; ix < g.nx; ++ix)
        for (const Offset& o : offsets) {
          const Index jx = ix + o.dx, jy = iy + o.dy;
          if (jx < 0 || jy < 0 || jx >= g.nx || jy >= g.ny) continue;
          add(g.index(ix, iy), g.index(jx, jy), o.cls);
        }
  }
  SpringSet finish() {
    std::stable_sort(raw_.begin(), raw_.end(), [](const Raw& a, const Raw& b) {
      return std::tie(a.a, a.b, a.cls) < std::tie(b.a, b.b, b.cls);
    });
    SpringSet s;
    const std::size_t S = raw_.size();
    s.i.reserve(S); s.j.reserve(S); s.rest_length.reserve(S);
    s.stiffness.reserve(S); s.damping.reserve(S); s.kind.reserve(S);
    for (const Raw& r : raw_) s.add(r.a, r.b, r.l0, k_[r.cls], c_[r.cls], r.cls);
    return s;
  }

 private:
  struct Raw {
    Index a, b;
    SpringClass cls;
    double l0;
  };
  const Mesh& mesh_;
  ClassValues k_, c_;
  std::vector<Raw> raw_;
};

}  // namespace

SpringSet build_springs(const Mesh& mesh, Stencil stencil, const ClassValues& stiffness,
                        const ClassValues& damping) {
  Builder b(mesh, stiffness, damping);
  if (stencil == Stencil::MeshEdges) {
    for (const auto& e : mesh.edges()) b.add(e[0], e[1], SpringClass::Edge);
    return b.finish();
  }
  if (!mesh.grid) throw std::invalid_argument("grid stencil on a mesh that is not a generated grid");
  const GridInfo& g = *mesh.grid;
  if (static_cast<std::int64_t>(g.nx) * g.ny != mesh.num_vertices())
    throw std::invalid_argument("grid info does not match the mesh's vertex count");
  constexpr auto St = SpringClass::Structural, Sh = SpringClass::Shear, Be = SpringClass::Bend;
  switch (stencil) {
    case Stencil::StructuralShearBend:
      b.add_offsets(g, {{1, 0, St}, {0, 1, St}, {1, 1, Sh}, {1, -1, Sh}, {2, 0, Be}, {0, 2, Be}});
      break;
    case Stencil::RadiusSqrt5:
      b.add_offsets(g, {{1, 0, St}, {0, 1, St}, {1, 1, Sh}, {1, -1, Sh}, {2, 0, Be}, {0, 2, Be},
                        {2, 1, Be}, {2, -1, Be}, {1, 2, Be}, {1, -2, Be}});
      break;
    case Stencil::KangChoTable1: {
      // (1) the triangulation's edges, (2) a bending spring across every interior edge
      // joining the two opposite vertices, (3) structural and both shear springs again.
      struct HalfEdge {
        Index lo, hi, opp;
      };
      std::vector<HalfEdge> he;
      he.reserve(mesh.triangles.size());
      const Index T = mesh.num_triangles();
      for (Index t = 0; t < T; ++t) {
        const Index* v = &mesh.triangles[3 * static_cast<std::size_t>(t)];
        for (int e = 0; e < 3; ++e) {
          const Index a = v[e], c = v[(e + 1) % 3], o = v[(e + 2) % 3];
          he.push_back({std::min(a, c), std::max(a, c), o});
        }
      }
      std::sort(he.begin(), he.end(),
                [](const HalfEdge& x, const HalfEdge& y) { return std::tie(x.lo, x.hi, x.opp) < std::tie(y.lo, y.hi, y.opp); });
      for (std::size_t q = 0; q < he.size();) {
        std::size_t r = q;
        while (r < he.size() && he[r].lo == he[q].lo && he[r].hi == he[q].hi) ++r;
        const Index a = he[q].lo, c = he[q].hi;
        const Index dx = std::abs(a % g.nx - c % g.nx), dy = std::abs(a / g.nx - c / g.nx);
        if (dx + dy == 1) b.add(a, c, St);
        else if (dx == 1 && dy == 1) b.add(a, c, Sh);
        else throw std::invalid_argument("kang_cho_table1: the mesh has a triangle edge that is not a grid edge or cell diagonal");
        if (r - q == 2) b.add(he[q].opp, he[q + 1].opp, Be);
        else if (r - q > 2) throw std::invalid_argument("kang_cho_table1: non-manifold edge in the grid mesh");
        q = r;
      }
      b.add_offsets(g, {{1, 0, St}, {0, 1, St}, {1, 1, Sh}, {1, -1, Sh}});
      break;
    }
    case Stencil::MeshEdges: break;
  }
  return b.finish();
}

namespace {

// Reads a value per spring class: a number, or a map {structural, shear, bend}. Missing map
// entries default to the structural value. Default, sign and units come from the spec.
ClassValues read_classes(const ParamReader& r, const std::string& key, bool single_class) {
  const ParamDecl& d = *r.spec().find(key);
  const double def = d.default_number;
  const bool positive = d.range.min_open;
  const char* unit = d.units.c_str();
  const Params node = r.node(key);  // asks for the key even when absent ("did you mean")
  if (!node.valid()) return ClassValues::all(def);
  auto check = [&](const Params& where, double x, const std::string& what) {
    const bool ok = std::isfinite(x) && (positive ? x > 0 : x >= 0);
    if (!ok) {
      std::ostringstream m;
      m << what << " must be " << (positive ? "a positive" : "a non-negative") << " number (" << unit
        << "), got " << x << "; fix the value";
      where.fail(m.str());
    }
  };
  if (node.is_scalar()) {
    const double x = node.as_double();
    check(node, x, key);
    return ClassValues::all(x);
  }
  if (!node.is_map())
    node.fail(key + " must be a number or a map {structural: ..., shear: ..., bend: ...}");
  if (single_class && (node.has("shear") || node.has("bend")))
    node.fail("stencil mesh_edges has a single spring class; give " + key +
              " as a number or as {structural: value}");
  ClassValues out;
  const double s = node.has("structural") ? node.child("structural").as_double() : def;
  if (node.has("structural")) check(node.child("structural"), s, key + ".structural");
  double sh = s, be = s;
  if (!single_class) {
    if (node.has("shear")) { sh = node.child("shear").as_double(); check(node.child("shear"), sh, key + ".shear"); }
    if (node.has("bend")) { be = node.child("bend").as_double(); check(node.child("bend"), be, key + ".bend"); }
  }
  node.check_unused();
  out.v = {s, sh, be, s};
  return out;
}

ParamSpec spring_classes(const std::string& what, const char* unit, const ParamRange& range) {
  ParamSpec c(what);
  c.number("structural", 0).no_default("the default of " + what).range(range).units(unit).help(
      "structural springs (all springs of mesh_edges)");
  c.number("shear", 0).no_default("structural").range(range).units(unit).help("shear (diagonal) springs of a grid stencil");
  c.number("bend", 0).no_default("structural").range(range).units(unit).help("bend (skip-one) springs of a grid stencil");
  return c;
}

}  // namespace

const ParamSpec& mass_spring_spec() {
  static const ParamSpec spec = [] {
    ParamSpec s("mass_spring", "Hooke springs on mesh edges or a grid stencil, axial dampers");
    s.choice("stencil", "mesh_edges", {"mesh_edges", "structural_shear_bend", "radius_sqrt5", "kang_cho_table1"})
        .default_text("structural_shear_bend on a grid mesh, mesh_edges on an OBJ mesh")
        .help("which vertex pairs get springs (grid stencils need mesh: {grid: ...})");
    s.number_or_map("stiffness", 2000.0, spring_classes("stiffness", "N/m", ParamRange::positive())).range(ParamRange::positive()).units("N/m")
        .help("spring constant: a number, or per class {structural, shear, bend}");
    s.number_or_map("damping", 0.0, spring_classes("damping", "N s/m", ParamRange::nonnegative())).range(ParamRange::nonnegative()).units("N s/m")
        .help("axial damper constant: a number, or per class {structural, shear, bend}");
    s.number("density", 0.1).range(ParamRange::positive()).units("kg/m^2").help(
        "areal density, lumped per triangle (give density or vertex_mass)");
    s.number("vertex_mass", 1.0).range(ParamRange::positive()).units("kg").default_text("none (density is used)").help(
        "the same mass for every vertex, instead of density");
    s.flag("clamp_compressed", true).help("springs shorter than their rest length exert no force");
    return s;
  }();
  return spec;
}

MassSpringMaterial::MassSpringMaterial(const Params& params, const Mesh& mesh) {
  const ParamReader r(params, mass_spring_spec());
  const Params& p = r.params();
  if (params.has("type")) params.mark_used("type");  // the framework's key (declared by the material section)
  n_ = mesh.num_vertices();
  const std::string def_stencil = mesh.grid ? "structural_shear_bend" : "mesh_edges";
  const std::string st = r.has("stencil") ? r.text("stencil") : def_stencil;
  parse_stencil(st, stencil_);
  if (stencil_ != Stencil::MeshEdges && !mesh.grid)
    p.child("stencil").fail("stencil " + st + " needs a generated grid mesh (mesh: {grid: ...}), but the mesh is '" +
                            mesh.source + "'; use stencil: mesh_edges for OBJ meshes");
  const bool single = stencil_ == Stencil::MeshEdges;
  const ClassValues k = read_classes(r, "stiffness", single);
  const ClassValues c = read_classes(r, "damping", single);
  clamp_ = r.flag("clamp_compressed");

  // Masses.
  const bool has_density = p.has("density"), has_vm = p.has("vertex_mass");
  if (has_density && has_vm)
    p.child("vertex_mass").fail("give either density (kg/m^2, lumped per triangle) or vertex_mass (kg per vertex), not both");
  mass_.assign(static_cast<std::size_t>(n_), 0.0);
  if (has_vm) {
    const double m = r.number("vertex_mass");
    std::fill(mass_.begin(), mass_.end(), m);
  } else {
    const double rho = r.number("density");
    const double* X = mesh.positions.data();
    for (Index t = 0; t < mesh.num_triangles(); ++t) {
      const Index* v = &mesh.triangles[3 * static_cast<std::size_t>(t)];
      const double* a = X + 3 * v[0];
      const double* b = X + 3 * v[1];
      const double* q = X + 3 * v[2];
      const double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
      const double e2[3] = {q[0] - a[0], q[1] - a[1], q[2] - a[2]};
      const double cx = e1[1] * e2[2] - e1[2] * e2[1], cy = e1[2] * e2[0] - e1[0] * e2[2],
                   cz = e1[0] * e2[1] - e1[1] * e2[0];
      const double area = 0.5 * std::sqrt(cx * cx + cy * cy + cz * cz);
      for (int r = 0; r < 3; ++r) mass_[v[r]] += rho * area / 3.0;
    }
    for (Index i = 0; i < n_; ++i)
      if (!(mass_[i] > 0))
        p.fail("vertex " + std::to_string(i) + " of mesh '" + mesh.source +
               "' gets no mass from density (it is in no triangle of non-zero area); use vertex_mass or fix the mesh");
  }

  // Springs.
  try {
    springs_ = build_springs(mesh, stencil_, k, c);
  } catch (const std::invalid_argument& e) {
    p.fail(std::string("cannot build stencil ") + st + " on mesh '" + mesh.source + "': " + e.what());
  }
  double scale = 0;
  for (double l : springs_.rest_length) scale = std::max(scale, l);
  for (Index s = 0; s < springs_.size(); ++s) {
    if (!(springs_.rest_length[s] > 1e-12 * scale) || !std::isfinite(springs_.rest_length[s])) {
      const Index a = springs_.i[s], b = springs_.j[s];
      std::ostringstream m;
      m << "spring between vertices " << a << " and " << b << " of mesh '" << mesh.source
        << "' has zero rest length (the vertices coincide at (" << mesh.positions[3 * a] << ", "
        << mesh.positions[3 * a + 1] << ", " << mesh.positions[3 * a + 2]
        << ")); merge duplicate vertices in the mesh";
      p.fail(m.str());
    }
  }
  if (springs_.size() == 0) p.fail("mesh '" + mesh.source + "' gives no springs for stencil " + st);
  damped_ = std::any_of(springs_.damping.begin(), springs_.damping.end(), [](double x) { return x > 0; });
  for (SpringClass cl : springs_.kind) ++counts_[static_cast<int>(cl)];
  {  // distinct vertex pairs (loom validate prints them when some pair has more than one spring)
    std::vector<std::uint64_t> key(static_cast<std::size_t>(springs_.size()));
    for (Index q = 0; q < springs_.size(); ++q) key[q] = spring_pair_key(springs_.i[q], springs_.j[q]);
    std::sort(key.begin(), key.end());
    pairs_ = static_cast<Index>(std::unique(key.begin(), key.end()) - key.begin());
  }

  layout_ = SpringLayout(n_, springs_);
  layout_.reorder(springs_);  // from here on, traversal position == spring index
  inv_rest_.resize(springs_.rest_length.size());
  for (std::size_t s = 0; s < inv_rest_.size(); ++s) inv_rest_[s] = 1.0 / springs_.rest_length[s];
}

void MassSpringMaterial::check_sizes(std::size_t xs, const char* what) const {
  if (xs != 3 * static_cast<std::size_t>(n_))
    throw std::invalid_argument(std::string("mass_spring: ") + what + " has " + std::to_string(xs) +
                                " entries, expected 3 x " + std::to_string(n_));
}

void MassSpringMaterial::compute_masses(std::span<double> mass) const {
  if (mass.size() != mass_.size()) throw std::invalid_argument("mass_spring: mass array has the wrong size");
  std::copy(mass_.begin(), mass_.end(), mass.begin());
}

void MassSpringMaterial::compute_forces(std::span<const double> x, std::span<const double> v,
                                        std::span<double> f) const {
  check_sizes(x.size(), "x");
  check_sizes(f.size(), "f");
  const double* X = x.data();
  double* F = f.data();
  const Index* I = springs_.i.data();
  const Index* J = springs_.j.data();
  const double* K = springs_.stiffness.data();
  const double* L0 = springs_.rest_length.data();
  auto zero = [F](Index v0, Index v1) { std::fill(F + 3 * static_cast<std::size_t>(v0), F + 3 * static_cast<std::size_t>(v1), 0.0); };
  // One pass over the springs in traversal order (stored so: position == spring index),
  // each thread scattering into its own part's vertices (SpringLayout). Variants measured
  // slower on the benchmark machine (docs/benchmarks/springs.md): a blocked SIMD loop
  // (gathers into a buffer, then a scatter); f_i summed in registers along runs of equal i
  // with interleaved endpoints and per-class k tables.
  if (!damped_) {
    layout_.for_each(zero, [=](Index s) {
      const Index a = I[s], b = J[s];
      double fi[3];
      kernels::spring_force(X + 3 * a, X + 3 * b, K[s], L0[s], fi);
      F[3 * a] += fi[0]; F[3 * a + 1] += fi[1]; F[3 * a + 2] += fi[2];
      F[3 * b] -= fi[0]; F[3 * b + 1] -= fi[1]; F[3 * b + 2] -= fi[2];
    });
  } else {
    check_sizes(v.size(), "v");
    const double* V = v.data();
    const double* C = springs_.damping.data();
    layout_.for_each(zero, [=](Index s) {
      const Index a = I[s], b = J[s];
      double fi[3];
      kernels::spring_force_damped(X + 3 * a, X + 3 * b, V + 3 * a, V + 3 * b, K[s], L0[s], C[s], fi);
      F[3 * a] += fi[0]; F[3 * a + 1] += fi[1]; F[3 * a + 2] += fi[2];
      F[3 * b] -= fi[0]; F[3 * b + 1] -= fi[1]; F[3 * b + 2] -= fi[2];
    });
  }
}

double MassSpringMaterial::elastic_energy(std::span<const double> x) const {
  check_sizes(x.size(), "x");
  const double* X = x.data();
  const Index S = springs_.size();
  double e = 0;
#pragma omp parallel for schedule(static) reduction(+ : e) if (S >= SpringLayout::kParallelMin)
  for (Index s = 0; s < S; ++s)
    e += kernels::spring_energy(X + 3 * springs_.i[s], X + 3 * springs_.j[s], springs_.stiffness[s],
                                springs_.rest_length[s]);
  return e;
}

double MassSpringMaterial::max_strain(std::span<const double> x) const {
  check_sizes(x.size(), "x");
  const double* X = x.data();
  const Index S = springs_.size();
  double m = 0;
#pragma omp parallel for schedule(static) reduction(max : m) if (S >= SpringLayout::kParallelMin)
  for (Index s = 0; s < S; ++s)
    m = std::max(m, std::abs(kernels::spring_strain(X + 3 * springs_.i[s], X + 3 * springs_.j[s], inv_rest_[s])));
  return m;
}

std::vector<std::pair<std::string, std::string>> MassSpringMaterial::describe() const {
  std::vector<std::pair<std::string, std::string>> d;
  d.emplace_back("stencil", to_string(stencil_));
  d.emplace_back("springs", std::to_string(springs_.size()));
  if (pairs_ < springs_.size())
    d.emplace_back("vertex pairs", std::to_string(pairs_) +
                                       " (symplectic_euler, rk4 and harmonic_oscillation step one merged spring per "
                                       "pair unless merge_springs: false)");
  const char* names[4] = {"structural", "shear", "bend", "edge"};
  for (int c = 0; c < 4; ++c)
    if (counts_[c] > 0) d.emplace_back(std::string(names[c]) + " springs", std::to_string(counts_[c]));
  std::ostringstream m;
  m << std::accumulate(mass_.begin(), mass_.end(), 0.0) << " kg";
  d.emplace_back("total mass", m.str());
  d.emplace_back("damped", damped_ ? "yes" : "no");
  d.emplace_back("layout", std::to_string(layout_.parts()) + " parts, " + std::to_string(layout_.num_cross()) +
                               " cross springs in " + std::to_string(layout_.num_colours()) + " colours");
  return d;
}

void MassSpringMaterial::jacobian_pairs(std::vector<std::array<Index, 2>>& pairs) const {
  pairs.reserve(pairs.size() + static_cast<std::size_t>(springs_.size()));
  for (Index s = 0; s < springs_.size(); ++s) pairs.push_back({springs_.i[s], springs_.j[s]});
}

void MassSpringMaterial::bind_pattern(const BsrPattern& pattern) {
  if (pattern.n != n_) throw std::invalid_argument("mass_spring: pattern size differs from the vertex count");
  pattern_ = &pattern;
  scatter_.resize(4 * static_cast<std::size_t>(springs_.size()));
  for (Index s = 0; s < springs_.size(); ++s) {
    const Index a = springs_.i[s], b = springs_.j[s];
    Index* m = &scatter_[4 * static_cast<std::size_t>(s)];
    m[0] = pattern.diag[a];
    m[1] = pattern.diag[b];
    m[2] = pattern.find(a, b);
    m[3] = pattern.find(b, a);
    if (m[0] < 0 || m[1] < 0 || m[2] < 0 || m[3] < 0)
      throw std::invalid_argument("mass_spring: the bound pattern lacks a block of spring " + std::to_string(s));
  }
  // First writers, in traversal order (== index order). Springs sharing a block share both
  // endpoints, so they run on the same thread in this order (same part, or colours in turn).
  first_write_.assign(static_cast<std::size_t>(springs_.size()), 0);
  std::vector<char> seen(static_cast<std::size_t>(pattern.nnz_blocks()), 0);
  for (Index s = 0; s < springs_.size(); ++s) {
    const Index* m = &scatter_[4 * static_cast<std::size_t>(s)];
    for (int e = 0; e < 2; ++e)
      if (!seen[m[2 + e]]) {
        seen[m[2 + e]] = 1;
        first_write_[s] |= static_cast<std::uint8_t>(1 << e);
      }
  }
  for (Index i = 0; i < n_; ++i) seen[pattern.diag[i]] = 1;
  assign_offdiag_ = std::all_of(seen.begin(), seen.end(), [](char c) { return c != 0; });
}

void MassSpringMaterial::compute_jacobians(std::span<const double> x, std::span<const double> v,
                                           BsrMatrix& dfdx, BsrMatrix* dfdv) const {
  (void)v;  // the damper Jacobian c n n^T depends on x only
  check_sizes(x.size(), "x");
  if (!pattern_ || !dfdx.has_pattern() || dfdx.pattern().nnz_blocks() != pattern_->nnz_blocks() ||
      (dfdv && (!dfdv->has_pattern() || dfdv->pattern().nnz_blocks() != pattern_->nnz_blocks())))
    throw std::logic_error("mass_spring: compute_jacobians before bind_pattern, or on another pattern");
  const double* X = x.data();
  const Index* I = springs_.i.data();
  const Index* J = springs_.j.data();
  const double* Ks = springs_.stiffness.data();
  const double* L0 = springs_.rest_length.data();
  const double* C = springs_.damping.data();
  const Index* M = scatter_.data();
  const Index* row_ptr = pattern_->row_ptr.data();
  double* A = dfdx.values().data();
  const bool with_v = dfdv != nullptr && damped_;
  double* B = with_v ? dfdv->values().data() : nullptr;
  if (dfdv && !damped_) dfdv->set_zero();
  const bool clamp = clamp_;
  const Index* diag = pattern_->diag.data();
  const std::uint8_t* first = first_write_.data();
  const bool assign = assign_offdiag_;
  auto zero = [=](Index v0, Index v1) {
    if (assign) {  // off-diagonal blocks are assigned by their first writer
      for (Index r = v0; r < v1; ++r) {
        std::fill(A + 9 * static_cast<std::size_t>(diag[r]), A + 9 * static_cast<std::size_t>(diag[r]) + 9, 0.0);
        if (B) std::fill(B + 9 * static_cast<std::size_t>(diag[r]), B + 9 * static_cast<std::size_t>(diag[r]) + 9, 0.0);
      }
    } else {
      std::fill(A + 9 * static_cast<std::size_t>(row_ptr[v0]), A + 9 * static_cast<std::size_t>(row_ptr[v1]), 0.0);
      if (B) std::fill(B + 9 * static_cast<std::size_t>(row_ptr[v0]), B + 9 * static_cast<std::size_t>(row_ptr[v1]), 0.0);
    }
  };
  // blk is symmetric, so block (j,i) = blk^T = blk.
  auto scatter = [](double* vals, const Index* m, std::uint8_t fw, const double* blk) {
    double* ii = vals + 9 * static_cast<std::size_t>(m[0]);
    double* jj = vals + 9 * static_cast<std::size_t>(m[1]);
    double* ij = vals + 9 * static_cast<std::size_t>(m[2]);
    double* ji = vals + 9 * static_cast<std::size_t>(m[3]);
    for (int q = 0; q < 9; ++q) {
      ii[q] -= blk[q];
      jj[q] -= blk[q];
    }
    if (fw & 1) {
      for (int q = 0; q < 9; ++q) ij[q] = blk[q];
    } else {
      for (int q = 0; q < 9; ++q) ij[q] += blk[q];
    }
    if (fw & 2) {
      for (int q = 0; q < 9; ++q) ji[q] = blk[q];
    } else {
      for (int q = 0; q < 9; ++q) ji[q] += blk[q];
    }
  };
  layout_.for_each(zero, [=](Index s) {
    const Index a = I[s], b = J[s];
    const Index* m = M + 4 * static_cast<std::size_t>(s);
    const std::uint8_t fw = assign ? first[s] : 0;
    double blk[9];
    kernels::spring_stiffness_block(X + 3 * a, X + 3 * b, Ks[s], L0[s], clamp, blk);
    scatter(A, m, fw, blk);
    if (B) {
      kernels::spring_damping_block(X + 3 * a, X + 3 * b, C[s], blk);
      scatter(B, m, fw, blk);
    }
  });
}

bool MassSpringMaterial::describe_device(DeviceDescription& out) const {
  ElementBlock b;
  b.kernel = ElementKernel::Spring;
  b.flags = clamp_ ? ElementBlock::kClampCompressed : 0u;
  const Index S = springs_.size();
  b.vertices.resize(2 * static_cast<std::size_t>(S));
  b.data.resize(3 * static_cast<std::size_t>(S));
  for (Index s = 0; s < S; ++s) {
    b.vertices[2 * s] = springs_.i[s];
    b.vertices[2 * s + 1] = springs_.j[s];
    b.data[3 * s] = springs_.rest_length[s];
    b.data[3 * s + 1] = springs_.stiffness[s];
    b.data[3 * s + 2] = springs_.damping[s];
  }
  out.blocks.push_back(std::move(b));
  return true;
}

}  // namespace loom::mass_spring
