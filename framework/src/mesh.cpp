#include "loom/mesh.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iostream>
#include <array>
#include <map>
#include <iterator>
#include <cstdlib>
#include <filesystem>
#include <sstream>

namespace loom {

std::vector<std::array<Index, 2>> Mesh::edges() const {
  std::vector<std::array<Index, 2>> e;
  e.reserve(triangles.size());
  for (std::size_t t = 0; t + 2 < triangles.size(); t += 3) {
    for (int k = 0; k < 3; ++k) {
      Index a = triangles[t + k], b = triangles[t + (k + 1) % 3];
      if (a > b) std::swap(a, b);
      e.push_back({a, b});
    }
  }
  std::sort(e.begin(), e.end());
  e.erase(std::unique(e.begin(), e.end()), e.end());
  return e;
}

Mesh make_grid(Index nx, Index ny, double width, double height, GridPlane plane, bool alternate_diagonals) {
  if (nx < 2 || ny < 2)
    throw InputError("grid: nx and ny must be at least 2 (got " + std::to_string(nx) + " x " + std::to_string(ny) + ")");
  if (!(width > 0) || !(height > 0) || !std::isfinite(width) || !std::isfinite(height))
    throw InputError("grid: width and height must be finite and > 0");
  if (static_cast<long long>(nx) * ny > 50'000'000LL) throw InputError("grid: more than 50 million vertices requested");
  Mesh m;
  m.grid = GridInfo{nx, ny, width, height};
  m.source = "grid " + std::to_string(nx) + "x" + std::to_string(ny);
  const std::size_t n = static_cast<std::size_t>(nx) * ny;
  m.positions.resize(3 * n);
  m.uvs.resize(2 * n);
  const double dx = width / (nx - 1), dy = height / (ny - 1);
  for (Index iy = 0; iy < ny; ++iy) {
    for (Index ix = 0; ix < nx; ++ix) {
      const std::size_t i = static_cast<std::size_t>(iy) * nx + ix;
      const double u = ix * dx, v = iy * dy;
      if (plane == GridPlane::XY) {
        m.positions[3 * i] = u; m.positions[3 * i + 1] = v; m.positions[3 * i + 2] = 0;
      } else {
        // Flat cloth: weft along x, warp along -z so that (x, -z, y) keeps the normal up (+y).
        m.positions[3 * i] = u; m.positions[3 * i + 1] = 0; m.positions[3 * i + 2] = -v;
      }
      m.uvs[2 * i] = u; m.uvs[2 * i + 1] = v;
    }
  }
  m.triangles.reserve(6 * static_cast<std::size_t>(nx - 1) * (ny - 1));
  for (Index iy = 0; iy + 1 < ny; ++iy) {
    for (Index ix = 0; ix + 1 < nx; ++ix) {
      const Index a = iy * nx + ix, b = a + 1, c = a + nx, d = c + 1;
      const bool flip = alternate_diagonals && ((ix + iy) % 2 == 1);
      if (!flip) {  // diagonal a-d
        m.triangles.insert(m.triangles.end(), {a, b, d, a, d, c});
      } else {      // diagonal b-c
        m.triangles.insert(m.triangles.end(), {a, b, c, b, d, c});
      }
    }
  }
  // No corner_uvs: a grid has no seams, so Mesh::corner_uv() reads each corner's vertex uv.
  return m;
}

namespace {

[[noreturn]] void obj_error(const std::string& path, int line, const std::string& msg) {
  throw InputError(path + ":" + std::to_string(line) + ": " + msg);
}

// Parse one OBJ index ("7", "-1", "7/2", "7//3", "7/2/3") into a 0-based vertex index.
Index parse_vertex_ref(const std::string& tok, Index nverts, const std::string& path, int line) {
  const std::string head = tok.substr(0, tok.find('/'));
  long long v = 0;
  std::size_t used = 0;
  try {
    v = std::stoll(head, &used);
  } catch (...) {
    obj_error(path, line, "bad face index '" + tok + "'. Fix: faces are 'f i j k' with 1-based vertex indices.");
  }
  if (used != head.size()) obj_error(path, line, "bad face index '" + tok + "'.");
  if (v < 0) v = nverts + v + 1;  // relative index
  if (v < 1 || v > nverts)
    obj_error(path, line, "face index " + head + " is out of range: the file has " + std::to_string(nverts) +
                              " vertices so far. Fix: indices are 1-based and refer to earlier 'v' lines.");
  return static_cast<Index>(v - 1);
}

}  // namespace

Mesh read_obj(const std::string& path, double area_tolerance) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec) || (std::filesystem::exists(path, ec) && !std::filesystem::is_regular_file(path, ec)))
    throw InputError(path + ": is not a regular file. Fix: give the path of an OBJ file.");
  std::ifstream file(path, std::ios::binary);
  if (!file) throw InputError(path + ": cannot open OBJ file (does it exist, and is it readable?)");
  // Line endings: LF, CRLF and old Mac CR-only files all read the same.
  std::string text((std::istreambuf_iterator<char>(file)), {});
  for (std::size_t k = 0; k < text.size(); ++k)
    if (text[k] == '\r') text[k] = (k + 1 < text.size() && text[k + 1] == '\n') ? ' ' : '\n';
  std::istringstream in(std::move(text));
  Mesh m;
  m.source = path;
  std::vector<double> vt;
  std::vector<long long> corner_vt;  // vt index (0-based) of each triangle corner, -1 if the face gave none
  std::vector<Index> vt_of_vertex;
  std::vector<int> tri_line;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ls(line);
    std::string tag;
    if (!(ls >> tag) || tag[0] == '#') continue;
    if (tag == "v") {
      double p[3];
      for (int k = 0; k < 3; ++k) {
        std::string t;
        if (!(ls >> t)) obj_error(path, lineno, "vertex needs 3 coordinates. Fix: 'v x y z'.");
        // strtod, not stod: a subnormal such as 4e-320 is a valid coordinate (stod rejects it
        // because strtod reports underflow).
        char* end = nullptr;
        p[k] = std::strtod(t.c_str(), &end);
        if (t.empty() || end != t.c_str() + t.size())
          obj_error(path, lineno, "vertex coordinate '" + t + "' is not a number.");
        if (!std::isfinite(p[k])) obj_error(path, lineno, "vertex coordinate is NaN or Inf. Fix the exporter or the file.");
      }
      m.positions.insert(m.positions.end(), p, p + 3);
      vt_of_vertex.push_back(-1);
    } else if (tag == "vt") {
      double u = 0, v = 0;
      if (!(ls >> u >> v) || !std::isfinite(u) || !std::isfinite(v))
        obj_error(path, lineno, "texture coordinate needs 2 finite numbers. Fix: 'vt u v'.");
      vt.push_back(u);
      vt.push_back(v);
    } else if (tag == "f") {
      std::vector<Index> poly;
      std::vector<long long> polyvt;
      std::string tok;
      const Index nv = static_cast<Index>(m.positions.size() / 3);
      while (ls >> tok) {
        poly.push_back(parse_vertex_ref(tok, nv, path, lineno));
        long long t = -1;
        const auto s1 = tok.find('/');
        if (s1 != std::string::npos) {
          const auto s2 = tok.find('/', s1 + 1);
          const std::string ts = tok.substr(s1 + 1, s2 == std::string::npos ? std::string::npos : s2 - s1 - 1);
          if (!ts.empty()) {
            try { t = std::stoll(ts); } catch (...) { obj_error(path, lineno, "bad texture index in '" + tok + "'."); }
            const long long nvt = static_cast<long long>(vt.size() / 2);
            if (t < 0) t = nvt + t + 1;
            if (t < 1 || t > nvt) obj_error(path, lineno, "texture index out of range in '" + tok + "'.");
            t -= 1;
          }
        }
        polyvt.push_back(t);
      }
      if (poly.size() < 3) obj_error(path, lineno, "a face needs at least 3 vertices.");
      for (std::size_t k = 0; k < poly.size(); ++k)
        if (polyvt[k] >= 0 && vt_of_vertex[poly[k]] < 0) vt_of_vertex[poly[k]] = static_cast<Index>(polyvt[k]);
      if (poly.size() > 3) {
        // Polygons are fanned from their first vertex. That is right only for convex
        // polygons: a concave one gives a triangle that faces the other way. Compare each fan
        // triangle with the polygon's (Newell) normal.
        double nn[3] = {0, 0, 0};
        for (std::size_t k = 0; k < poly.size(); ++k) {
          const double* a = &m.positions[3 * static_cast<std::size_t>(poly[k])];
          const double* b = &m.positions[3 * static_cast<std::size_t>(poly[(k + 1) % poly.size()])];
          nn[0] += (a[1] - b[1]) * (a[2] + b[2]);
          nn[1] += (a[2] - b[2]) * (a[0] + b[0]);
          nn[2] += (a[0] - b[0]) * (a[1] + b[1]);
        }
        for (std::size_t k = 1; k + 1 < poly.size(); ++k) {
          const double* a = &m.positions[3 * static_cast<std::size_t>(poly[0])];
          const double* b = &m.positions[3 * static_cast<std::size_t>(poly[k])];
          const double* c = &m.positions[3 * static_cast<std::size_t>(poly[k + 1])];
          const double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
          const double cr[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
          if (cr[0] * nn[0] + cr[1] * nn[1] + cr[2] * nn[2] < 0)
            obj_error(path, lineno, "this " + std::to_string(poly.size()) + "-sided face is not convex: splitting it "
                                    "into a fan from its first vertex gives a flipped triangle. Fix: triangulate the mesh "
                                    "in your modelling tool (Blender: Triangulate modifier, 'Beauty') before loading it.");
        }
      }
      for (std::size_t k = 1; k + 1 < poly.size(); ++k) {
        m.triangles.insert(m.triangles.end(), {poly[0], poly[k], poly[k + 1]});
        corner_vt.insert(corner_vt.end(), {polyvt[0], polyvt[k], polyvt[k + 1]});
        tri_line.push_back(lineno);
      }
    }
    // other tags (vn, o, g, s, usemtl, mtllib, l) are ignored
  }
  if (m.positions.empty()) throw InputError(path + ": no vertices ('v' lines) found. Fix: give a triangle mesh in OBJ format.");
  if (m.triangles.empty()) throw InputError(path + ": no faces ('f' lines) found. Fix: Loom needs a triangle mesh.");
  // Degenerate triangles: repeated vertices or (near) zero area relative to the edge lengths.
  double mean_e2 = 0;
  const std::size_t nt = m.triangles.size() / 3;
  for (std::size_t t = 0; t < nt; ++t) {
    const Index* T = &m.triangles[3 * t];
    for (int k = 0; k < 3; ++k) {
      const double* a = &m.positions[3 * T[k]];
      const double* b = &m.positions[3 * T[(k + 1) % 3]];
      mean_e2 += (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]);
    }
  }
  mean_e2 /= 3.0 * nt;
  for (std::size_t t = 0; t < nt; ++t) {
    const Index* T = &m.triangles[3 * t];
    if (T[0] == T[1] || T[1] == T[2] || T[0] == T[2])
      obj_error(path, tri_line[t], "degenerate face: a vertex is repeated. Fix: remove the face or merge it.");
    const double* a = &m.positions[3 * T[0]];
    const double* b = &m.positions[3 * T[1]];
    const double* c = &m.positions[3 * T[2]];
    const double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double cr[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
    const double area = 0.5 * std::sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
    if (!(area > area_tolerance * mean_e2))
      obj_error(path, tri_line[t], "degenerate face (zero area: its vertices are collinear or coincide). "
                                   "Fix: remove it or clean the mesh (e.g. Blender's 'Merge by distance').");
  }
  // Duplicate faces (the same three vertices twice) are an error; edges shared by three or
  // more triangles (non-manifold) are a warning: membranes simulate them, but hinge bending
  // refuses them and contact normals are ambiguous there (docs/ARCHITECTURE.md, meshes).
  {
    std::map<std::array<Index, 3>, std::size_t> faces;
    std::map<std::array<Index, 2>, int> edge_use;
    for (std::size_t t = 0; t < nt; ++t) {
      std::array<Index, 3> key{m.triangles[3 * t], m.triangles[3 * t + 1], m.triangles[3 * t + 2]};
      std::sort(key.begin(), key.end());
      const auto [it, fresh] = faces.emplace(key, t);
      if (!fresh)
        obj_error(path, tri_line[t], "duplicate face: vertices " + std::to_string(key[0] + 1) + ", " +
                                         std::to_string(key[1] + 1) + ", " + std::to_string(key[2] + 1) +
                                         " already form the face on line " + std::to_string(tri_line[it->second]) +
                                         ". Fix: delete one of them (Blender: Mesh > Clean Up > Delete Loose / Merge by distance).");
      for (int k = 0; k < 3; ++k) {
        const Index a = m.triangles[3 * t + k], b = m.triangles[3 * t + (k + 1) % 3];
        edge_use[{std::min(a, b), std::max(a, b)}] += 1;
      }
    }
    int shown = 0, non_manifold = 0;
    for (const auto& [e, uses] : edge_use)
      if (uses > 2) {
        ++non_manifold;
        if (shown++ < 3)
          std::cerr << "loom: warning: " << path << ": edge between vertices " << e[0] + 1 << " and " << e[1] + 1
                    << " is shared by " << uses << " triangles (non-manifold). Membranes simulate it; bending refuses "
                    << "it. Fix: split the edge in your modelling tool if the cloth should not branch there.\n";
      }
    if (non_manifold > 3)
      std::cerr << "loom: warning: " << path << ": " << non_manifold << " non-manifold edges in all.\n";
  }
  // UVs: only when every vertex got one. Per vertex: the vt of its first use. Per corner: the
  // face's own vt (different on either side of a UV seam), or the vertex's first-use vt for a
  // corner whose face gave none.
  if (!vt.empty() && std::all_of(vt_of_vertex.begin(), vt_of_vertex.end(), [](Index t) { return t >= 0; })) {
    m.uvs.resize(2 * vt_of_vertex.size());
    for (std::size_t i = 0; i < vt_of_vertex.size(); ++i) {
      m.uvs[2 * i] = vt[2 * vt_of_vertex[i]];
      m.uvs[2 * i + 1] = vt[2 * vt_of_vertex[i] + 1];
    }
    m.corner_uvs.resize(2 * m.triangles.size());
    for (std::size_t c = 0; c < m.triangles.size(); ++c) {
      const std::size_t t = corner_vt[c] >= 0 ? static_cast<std::size_t>(corner_vt[c])
                                               : static_cast<std::size_t>(vt_of_vertex[m.triangles[c]]);
      m.corner_uvs[2 * c] = vt[2 * t];
      m.corner_uvs[2 * c + 1] = vt[2 * t + 1];
    }
  }
  return m;
}

}  // namespace loom
