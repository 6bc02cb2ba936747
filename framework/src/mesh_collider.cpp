#include "loom/mesh_collider.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "loom/mesh.hpp"

namespace loom {

namespace {

inline double dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline void sub3(const double* a, const double* b, double* r) {
  r[0] = a[0] - b[0];
  r[1] = a[1] - b[1];
  r[2] = a[2] - b[2];
}
inline void cross3(const double* a, const double* b, double* r) {
  r[0] = a[1] * b[2] - a[2] * b[1];
  r[1] = a[2] * b[0] - a[0] * b[2];
  r[2] = a[0] * b[1] - a[1] * b[0];
}
inline void normalize3(double* a) {
  const double l = std::sqrt(dot3(a, a));
  if (l > 0)
    for (int k = 0; k < 3; ++k) a[k] /= l;
}

// The OBJ line of every triangle (polygons are fanned into n - 2 triangles, as read_obj does).
std::vector<int> face_lines_of(const std::string& path) {
  std::vector<int> lines;
  std::ifstream in(path);
  std::string line, tag, tok;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    std::istringstream ls(line);
    if (!(ls >> tag) || tag != "f") continue;
    int n = 0;
    while (ls >> tok) ++n;
    for (int k = 0; k + 2 < n; ++k) lines.push_back(lineno);
  }
  return lines;
}

}  // namespace

std::shared_ptr<MeshBody> MeshBody::load(const std::string& path, double scale, const std::array<double, 3>& offset) {
  if (!std::ifstream(path))
    throw InputError(path + ": cannot open the collider's OBJ file. Fix: check the 'obj' path (relative paths resolve "
                     "against the scene file's folder).");
  Mesh m = read_obj(path);  // InputError with file:line for NaN/Inf, bad indices, degenerate faces, no faces
  for (std::size_t i = 0; i < m.positions.size(); ++i) m.positions[i] = m.positions[i] * scale + offset[i % 3];
  return build(std::move(m.positions), std::move(m.triangles), path, face_lines_of(path));
}

std::shared_ptr<MeshBody> MeshBody::build(std::vector<double> positions, std::vector<Index> triangles,
                                          const std::string& source, const std::vector<int>& face_lines) {
  auto body = std::make_shared<MeshBody>();
  MeshBody& b = *body;
  b.source_ = source;
  b.x_ = std::move(positions);
  b.tri_ = std::move(triangles);
  const Index nt = b.num_triangles(), nv = b.num_vertices();
  if (nt == 0) throw InputError(source + ": the collider mesh has no faces. Fix: give a triangle mesh.");
  auto where = [&](Index t) {
    return t < static_cast<Index>(face_lines.size()) ? source + ":" + std::to_string(face_lines[t])
                                                     : source + " (face " + std::to_string(t) + ")";
  };
  for (double c : b.x_)
    if (!std::isfinite(c)) throw InputError(source + ": a vertex coordinate is NaN or Inf. Fix the file.");

  // Edges: at most two faces each, traversed in opposite directions (a consistently oriented
  // 2-manifold, possibly with boundary).
  std::map<std::pair<Index, Index>, std::vector<std::pair<Index, int>>> edges;  // (lo, hi) -> (face, local edge)
  for (Index t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      const Index i = b.tri_[3 * t + k], j = b.tri_[3 * t + (k + 1) % 3];
      edges[{std::min(i, j), std::max(i, j)}].push_back({t, k});
    }
  bool closed = true;
  for (const auto& [e, fs] : edges) {
    if (fs.size() > 2)
      throw InputError(where(fs[2].first) + ": non-manifold collider mesh: the edge between vertices " +
                       std::to_string(e.first + 1) + " and " + std::to_string(e.second + 1) + " has " +
                       std::to_string(fs.size()) + " faces (also at " + where(fs[0].first) + " and " +
                       where(fs[1].first) +
                       "). Fix: give a 2-manifold mesh (each edge shared by at most two faces), e.g. split the "
                       "body into separate colliders.");
    if (fs.size() == 1) closed = false;
    if (fs.size() == 2) {
      const Index a0 = b.tri_[3 * fs[0].first + fs[0].second];
      const Index a1 = b.tri_[3 * fs[1].first + fs[1].second];
      if (a0 == a1)
        throw InputError(where(fs[1].first) + ": inconsistent face orientation in the collider mesh: this face and " +
                         where(fs[0].first) + " traverse the edge between vertices " + std::to_string(e.first + 1) +
                         " and " + std::to_string(e.second + 1) +
                         " in the same direction. Fix: wind all faces the same way (counter-clockwise seen from "
                         "outside), e.g. Blender's Recalculate Outside.");
    }
  }
  b.closed_ = closed;
  // A closed mesh wound inward (negative volume) is flipped so that normals point out.
  if (closed) {
    double vol = 0;
    for (Index t = 0; t < nt; ++t) {
      double c[3];
      cross3(&b.x_[3 * b.tri_[3 * t + 1]], &b.x_[3 * b.tri_[3 * t + 2]], c);
      vol += dot3(&b.x_[3 * b.tri_[3 * t]], c);
    }
    if (vol < 0)
      for (Index t = 0; t < nt; ++t) std::swap(b.tri_[3 * t + 1], b.tri_[3 * t + 2]);
  }

  // Face normals, angle-weighted vertex pseudo-normals, edge pseudo-normals.
  b.face_n_.assign(3 * static_cast<std::size_t>(nt), 0.0);
  b.vert_n_.assign(3 * static_cast<std::size_t>(nv), 0.0);
  b.edge_n_.assign(9 * static_cast<std::size_t>(nt), 0.0);
  for (Index t = 0; t < nt; ++t) {
    const Index* T = &b.tri_[3 * t];
    double e1[3], e2[3], n[3];
    sub3(&b.x_[3 * T[1]], &b.x_[3 * T[0]], e1);
    sub3(&b.x_[3 * T[2]], &b.x_[3 * T[0]], e2);
    cross3(e1, e2, n);
    if (!(dot3(n, n) > 0))
      throw InputError(where(t) + ": degenerate (zero-area) face in the collider mesh. Fix: remove it.");
    normalize3(n);
    std::copy(n, n + 3, &b.face_n_[3 * t]);
    for (int k = 0; k < 3; ++k) {
      double u[3], w[3];
      sub3(&b.x_[3 * T[(k + 1) % 3]], &b.x_[3 * T[k]], u);
      sub3(&b.x_[3 * T[(k + 2) % 3]], &b.x_[3 * T[k]], w);
      const double cosang = dot3(u, w) / std::sqrt(dot3(u, u) * dot3(w, w));
      const double ang = std::acos(std::clamp(cosang, -1.0, 1.0));
      for (int c = 0; c < 3; ++c) b.vert_n_[3 * T[k] + c] += ang * n[c];
    }
  }
  for (Index v = 0; v < nv; ++v) normalize3(&b.vert_n_[3 * v]);
  for (const auto& [e, fs] : edges) {
    double n[3] = {0, 0, 0};
    for (const auto& f : fs)
      for (int c = 0; c < 3; ++c) n[c] += b.face_n_[3 * f.first + c];
    normalize3(n);
    for (const auto& f : fs) std::copy(n, n + 3, &b.edge_n_[9 * f.first + 3 * f.second]);
  }
  // Unused vertices get no normal; they are never a nearest feature.

  // Bounding box centre (the default pivot) and the hierarchy.
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (Index v = 0; v < nv; ++v)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], b.x_[3 * v + k]);
      hi[k] = std::max(hi[k], b.x_[3 * v + k]);
    }
  for (int k = 0; k < 3; ++k) b.center_[k] = 0.5 * (lo[k] + hi[k]);
  std::vector<double> centroid(3 * static_cast<std::size_t>(nt));
  for (Index t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k)
      centroid[3 * t + k] =
          (b.x_[3 * b.tri_[3 * t] + k] + b.x_[3 * b.tri_[3 * t + 1] + k] + b.x_[3 * b.tri_[3 * t + 2] + k]) / 3.0;
  b.order_.resize(nt);
  for (Index t = 0; t < nt; ++t) b.order_[t] = t;
  b.nodes_.reserve(2 * static_cast<std::size_t>(nt));
  b.build_node(0, nt, centroid);
  return body;
}

// Median split along the longest axis of the centroids' box; leaves of up to 4 triangles.
Index MeshBody::build_node(Index begin, Index end, std::vector<double>& centroid) {
  const Index id = static_cast<Index>(nodes_.size());
  nodes_.push_back({});
  Node nd{};
  for (int k = 0; k < 3; ++k) {
    nd.lo[k] = INFINITY;
    nd.hi[k] = -INFINITY;
  }
  double clo[3] = {INFINITY, INFINITY, INFINITY}, chi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (Index i = begin; i < end; ++i) {
    const Index t = order_[i];
    for (int v = 0; v < 3; ++v)
      for (int k = 0; k < 3; ++k) {
        nd.lo[k] = std::min(nd.lo[k], x_[3 * tri_[3 * t + v] + k]);
        nd.hi[k] = std::max(nd.hi[k], x_[3 * tri_[3 * t + v] + k]);
      }
    for (int k = 0; k < 3; ++k) {
      clo[k] = std::min(clo[k], centroid[3 * t + k]);
      chi[k] = std::max(chi[k], centroid[3 * t + k]);
    }
  }
  if (end - begin <= 4) {
    nd.first = begin;
    nd.count = end - begin;
    nd.right = -1;
    nodes_[id] = nd;
    return id;
  }
  int axis = 0;
  for (int k = 1; k < 3; ++k)
    if (chi[k] - clo[k] > chi[axis] - clo[axis]) axis = k;
  const Index mid = begin + (end - begin) / 2;
  std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                   [&](Index a, Index c) { return centroid[3 * a + axis] < centroid[3 * c + axis]; });
  nd.count = 0;
  nd.first = build_node(begin, mid, centroid);
  nd.right = build_node(mid, end, centroid);
  nodes_[id] = nd;
  return id;
}

kernels::MeshView MeshBody::view() const {
  kernels::MeshView m;
  m.x = x_.data();
  m.tri = tri_.data();
  m.face_n = face_n_.data();
  m.vert_n = vert_n_.data();
  m.edge_n = edge_n_.data();
  m.nodes = nodes_.data();
  m.order = order_.data();
  m.closed = closed_ ? 1 : 0;
  return m;
}

// The queries: one source with the CUDA backend (loom/kernels/mesh_query.hpp).
MeshBody::Nearest MeshBody::nearest(const double p[3]) const {
  Nearest best{};
  kernels::mesh_nearest_within(view(), p, INFINITY, best);
  return best;
}

double MeshBody::signed_distance(const double p[3], double normal[3], double point[3]) const {
  return kernels::mesh_signed_distance(view(), p, normal, point, INFINITY);
}

double MeshBody::signed_distance(const double p[3], double normal[3], double point[3], double cutoff) const {
  return kernels::mesh_signed_distance(view(), p, normal, point, cutoff);
}

}  // namespace loom
