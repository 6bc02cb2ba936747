// An independent triangle-triangle intersection counter for the tests (it shares no code with
// framework/src/self_collision.cpp). Two triangles without a shared vertex intersect iff an
// edge of one crosses the other triangle (the coplanar case is counted by 2-D edge-edge and
// containment tests). Orientation signs are computed in double precision with a forward error
// bound: a sign within rounding error counts as zero, and a zero sign never makes a crossing.
// So every transversal intersection is counted; configurations that only touch, or whose signs
// rounding cannot decide (e.g. a flat sheet whose heights differ in the last bit), are not.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <span>
#include <vector>

#include "loom/mesh.hpp"

namespace tritest {

using P = std::array<double, 3>;

inline int sgn(double v) { return (v > 0) - (v < 0); }

// Sign of the orientation determinant of (a, b, c, d), 0 when rounding could flip it
// (bound after Shewchuk's orient3d filter, with a generous constant).
inline int orient3d(const P& a, const P& b, const P& c, const P& d) {
  const double ax = a[0] - d[0], ay = a[1] - d[1], az = a[2] - d[2];
  const double bx = b[0] - d[0], by = b[1] - d[1], bz = b[2] - d[2];
  const double cx = c[0] - d[0], cy = c[1] - d[1], cz = c[2] - d[2];
  const double det = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx);
  const double perm = std::abs(ax) * (std::abs(by * cz) + std::abs(bz * cy)) +
                      std::abs(ay) * (std::abs(bx * cz) + std::abs(bz * cx)) +
                      std::abs(az) * (std::abs(bx * cy) + std::abs(by * cx));
  return std::abs(det) <= 1e-14 * perm ? 0 : sgn(det);
}

// Segment pq against triangle abc (not coplanar): proper or touching crossing.
inline bool segment_crosses_triangle(const P& p, const P& q, const P& a, const P& b, const P& c) {
  const int sp = orient3d(a, b, c, p), sq = orient3d(a, b, c, q);
  if (sp * sq >= 0) return false;  // same side, or touching / undecided
  const int s1 = orient3d(p, q, a, b), s2 = orient3d(p, q, b, c), s3 = orient3d(p, q, c, a);
  return (s1 < 0 && s2 < 0 && s3 < 0) || (s1 > 0 && s2 > 0 && s3 > 0);
}

inline double orient2d(const double* a, const double* b, const double* c) {
  return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

// Coplanar triangles: project to the plane's dominant axes and test edges and containment.
inline bool coplanar_overlap(const std::array<P, 3>& t, const std::array<P, 3>& u) {
  const P e1{t[1][0] - t[0][0], t[1][1] - t[0][1], t[1][2] - t[0][2]};
  const P e2{t[2][0] - t[0][0], t[2][1] - t[0][1], t[2][2] - t[0][2]};
  const P nrm{e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
  int drop = 0;
  for (int k = 1; k < 3; ++k)
    if (std::abs(nrm[k]) > std::abs(nrm[drop])) drop = k;
  const int i0 = drop == 0 ? 1 : 0, i1 = drop == 2 ? 1 : 2;
  double A[3][2], B[3][2];
  for (int k = 0; k < 3; ++k) {
    A[k][0] = t[k][i0], A[k][1] = t[k][i1];
    B[k][0] = u[k][i0], B[k][1] = u[k][i1];
  }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const double *a = A[i], *b = A[(i + 1) % 3], *c = B[j], *d = B[(j + 1) % 3];
      const double o1 = orient2d(a, b, c), o2 = orient2d(a, b, d), o3 = orient2d(c, d, a), o4 = orient2d(c, d, b);
      if (sgn(o1) * sgn(o2) < 0 && sgn(o3) * sgn(o4) < 0) return true;
    }
  auto inside = [](const double T[3][2], const double* p) {
    const double a = orient2d(T[0], T[1], p), b = orient2d(T[1], T[2], p), c = orient2d(T[2], T[0], p);
    return (a > 0 && b > 0 && c > 0) || (a < 0 && b < 0 && c < 0);
  };
  return inside(A, B[0]) || inside(B, A[0]);
}

inline bool triangles_intersect(const std::array<P, 3>& t, const std::array<P, 3>& u) {
  const int s0 = orient3d(t[0], t[1], t[2], u[0]), s1 = orient3d(t[0], t[1], t[2], u[1]),
            s2 = orient3d(t[0], t[1], t[2], u[2]);
  if (s0 == 0 && s1 == 0 && s2 == 0) return coplanar_overlap(t, u);
  if ((s0 > 0 && s1 > 0 && s2 > 0) || (s0 < 0 && s1 < 0 && s2 < 0)) return false;
  for (int i = 0; i < 3; ++i) {
    if (segment_crosses_triangle(t[i], t[(i + 1) % 3], u[0], u[1], u[2])) return true;
    if (segment_crosses_triangle(u[i], u[(i + 1) % 3], t[0], t[1], t[2])) return true;
  }
  return false;
}

/// Number of intersecting pairs of triangles that share no vertex (O(n^2) with a box filter).
inline int count_intersecting_pairs(const loom::Mesh& mesh, std::span<const double> x) {
  const loom::Index nt = mesh.num_triangles();
  std::vector<std::array<P, 3>> tri(nt);
  std::vector<std::array<double, 6>> box(nt);
  for (loom::Index t = 0; t < nt; ++t) {
    std::array<double, 6> b{1e300, 1e300, 1e300, -1e300, -1e300, -1e300};
    for (int k = 0; k < 3; ++k) {
      const loom::Index v = mesh.triangles[3 * t + k];
      for (int q = 0; q < 3; ++q) {
        tri[t][k][q] = x[3 * v + q];
        b[q] = std::min(b[q], x[3 * v + q]);
        b[3 + q] = std::max(b[3 + q], x[3 * v + q]);
      }
    }
    box[t] = b;
  }
  int count = 0;
  for (loom::Index a = 0; a < nt; ++a)
    for (loom::Index b = a + 1; b < nt; ++b) {
      const auto &A = box[a], &B = box[b];
      if (A[0] > B[3] || B[0] > A[3] || A[1] > B[4] || B[1] > A[4] || A[2] > B[5] || B[2] > A[5]) continue;
      bool shared = false;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) shared |= mesh.triangles[3 * a + i] == mesh.triangles[3 * b + j];
      if (shared) continue;
      if (triangles_intersect(tri[a], tri[b])) ++count;
    }
  return count;
}

}  // namespace tritest
