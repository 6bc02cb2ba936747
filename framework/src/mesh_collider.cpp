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

// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5), with
// the feature it lies on: 0..2 vertex k, 3..5 edge (k, k+1) for k = feature - 3, 6 interior.
int closest_on_triangle(const double* p, const double* a, const double* b, const double* c, double* q) {
  double ab[3], ac[3], ap[3];
  sub3(b, a, ab);
  sub3(c, a, ac);
  sub3(p, a, ap);
  const double d1 = dot3(ab, ap), d2 = dot3(ac, ap);
  if (d1 <= 0 && d2 <= 0) {
    std::copy(a, a + 3, q);
    return 0;
  }
  double bp[3];
  sub3(p, b, bp);
  const double d3 = dot3(ab, bp), d4 = dot3(ac, bp);
  if (d3 >= 0 && d4 <= d3) {
    std::copy(b, b + 3, q);
    return 1;
  }
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    for (int k = 0; k < 3; ++k) q[k] = a[k] + v * ab[k];
    return 3;  // edge a-b
  }
  double cp[3];
  sub3(p, c, cp);
  const double d5 = dot3(ab, cp), d6 = dot3(ac, cp);
  if (d6 >= 0 && d5 <= d6) {
    std::copy(c, c + 3, q);
    return 2;
  }
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    for (int k = 0; k < 3; ++k) q[k] = a[k] + w * ac[k];
    return 5;  // edge c-a
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    for (int k = 0; k < 3; ++k) q[k] = b[k] + w * (c[k] - b[k]);
    return 4;  // edge b-c
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  for (int k = 0; k < 3; ++k) q[k] = a[k] + ab[k] * v + ac[k] * w;
  return 6;
}

double box_distance2(const double* lo, const double* hi, const double* p) {
  double d2 = 0;
  for (int k = 0; k < 3; ++k) {
    const double d = p[k] < lo[k] ? lo[k] - p[k] : (p[k] > hi[k] ? p[k] - hi[k] : 0.0);
    d2 += d * d;
  }
  return d2;
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

MeshBody::Nearest MeshBody::nearest(const double p[3]) const {
  Nearest best{};
  nearest_within(p, INFINITY, best);
  return best;
}

bool MeshBody::nearest_within(const double p[3], double limit2, Nearest& best) const {
  double best_d2 = limit2;
  int best_feature = -1;
  Index stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& nd = nodes_[stack[--top]];
    if (box_distance2(nd.lo, nd.hi, p) >= best_d2) continue;
    if (nd.count > 0) {
      for (Index i = nd.first; i < nd.first + nd.count; ++i) {
        const Index t = order_[i];
        double q[3];
        const int f = closest_on_triangle(p, &x_[3 * tri_[3 * t]], &x_[3 * tri_[3 * t + 1]], &x_[3 * tri_[3 * t + 2]], q);
        double d[3];
        sub3(p, q, d);
        const double d2 = dot3(d, d);
        if (d2 < best_d2) {
          best_d2 = d2;
          best_feature = f;
          best.face = t;
          std::copy(q, q + 3, best.point);
        }
      }
      continue;
    }
    // Visit the nearer child first (pushed last).
    const Node& l = nodes_[nd.first];
    const Node& r = nodes_[nd.right];
    const double dl = box_distance2(l.lo, l.hi, p), dr = box_distance2(r.lo, r.hi, p);
    if (top + 2 > 128) continue;  // depth is ~log2(n / 4) + 1: never reached for any real mesh
    if (dl < dr) {
      stack[top++] = nd.right;
      stack[top++] = nd.first;
    } else {
      stack[top++] = nd.first;
      stack[top++] = nd.right;
    }
  }
  if (best_feature < 0) return false;
  best.distance = std::sqrt(best_d2);
  const double* n = best_feature < 3   ? &vert_n_[3 * tri_[3 * best.face + best_feature]]
                    : best_feature < 6 ? &edge_n_[9 * best.face + 3 * (best_feature - 3)]
                                       : &face_n_[3 * best.face];
  std::copy(n, n + 3, best.normal);
  return true;
}

double MeshBody::signed_from(const double p[3], const Nearest& nr, double normal[3], double point[3]) const {
  double d[3];
  sub3(p, nr.point, d);
  const double s = dot3(d, nr.normal) < 0 ? -1.0 : 1.0;
  std::copy(nr.point, nr.point + 3, point);
  // The direction to the point (outward: flipped inside) is the contact normal, except on the
  // surface itself, where the pseudo-normal is.
  if (nr.distance > 1e-12) {
    for (int k = 0; k < 3; ++k) normal[k] = s * d[k] / nr.distance;
  } else {
    std::copy(nr.normal, nr.normal + 3, normal);
  }
  return s * nr.distance;
}

double MeshBody::signed_distance(const double p[3], double normal[3], double point[3]) const {
  return signed_from(p, nearest(p), normal, point);
}

double MeshBody::signed_distance(const double p[3], double normal[3], double point[3], double cutoff) const {
  const Node& root = nodes_[0];
  const double box2 = box_distance2(root.lo, root.hi, p);
  Nearest nr{};
  if (closed_ && box2 > 0) {
    // Outside the box of a closed mesh is outside the body: farther than the box distance.
    auto far = [&](double bound) {
      for (int k = 0; k < 3; ++k) normal[k] = 0, point[k] = p[k];
      return bound;
    };
    if (box2 >= cutoff * cutoff) return far(std::sqrt(box2));
    if (!nearest_within(p, cutoff * cutoff, nr)) return far(cutoff);
    return signed_from(p, nr, normal, point);
  }
  // Inside the box (or an open mesh, whose back side counts as inside): the sign needs the
  // nearest face wherever it is.
  if (!nearest_within(p, cutoff * cutoff, nr)) nearest_within(p, INFINITY, nr);
  return signed_from(p, nr, normal, point);
}

}  // namespace loom
