// The mesh collider's geometry as plain arrays and LOOM_HD functions: the closest point on a
// triangle, the stack-based traversal of the flattened bounding-volume hierarchy, the signed
// distance from the angle-weighted pseudo-normal, and the collider query (a point moved into
// the body frame by the collider's rigid placement, the answer moved back). One source: the
// CPU's MeshBody and Collider::query (framework/src) call these on host vectors, and the CUDA
// backend calls them on device copies of the same arrays (plugins/backends/cuda), so both
// backends find the same nearest feature, normal and distance. Always double: the float
// device path converts its point to double for the query. No allocation, no recursion.
#pragma once

#include <cmath>

#include "loom/common.hpp"

// The descent and the collider query are kept out of line: a kernel asks several queries
// (Baraff-Witkin's constraint pass three per collider), and inlining the descent into each
// site of each kernel multiplies nvcc's compile time. One compiled copy also means the CPU and
// the OpenMP stand-in run the very same instructions.
#if defined(__CUDACC__)
#define LOOM_MESH_NOINLINE __noinline__
#else
#define LOOM_MESH_NOINLINE __attribute__((noinline))
#endif

namespace loom::kernels {

/// One node of the flattened hierarchy (node 0 is the root).
struct MeshNode {
  double lo[3], hi[3];
  Index first;  ///< leaf: first entry of `order`; inner: left child
  Index count;  ///< leaf: number of triangles (> 0); inner: 0
  Index right;  ///< inner: right child
};

/// A collider mesh in its body frame, as pointers to plain arrays (host or device).
struct MeshView {
  const double* x = nullptr;       ///< 3 per vertex
  const Index* tri = nullptr;      ///< 3 per face
  const double* face_n = nullptr;  ///< 3 per face
  const double* vert_n = nullptr;  ///< 3 per vertex (angle weighted)
  const double* edge_n = nullptr;  ///< 9 per face: edge k = (v_k, v_k+1)
  const MeshNode* nodes = nullptr;
  const Index* order = nullptr;    ///< triangles in leaf order
  int closed = 0;
};

struct MeshNearest {
  double point[3];   ///< nearest point on the mesh
  double normal[3];  ///< pseudo-normal of the nearest feature (unit, outward)
  double distance;   ///< unsigned distance
  Index face;
};

/// A mesh collider placed at one time (Collider::frame_at): body -> world is
/// x = R (y - pivot) + center.
struct MeshPlacement {
  double center[3] = {0, 0, 0};  ///< reference point c(t)
  double pivot[3] = {0, 0, 0};   ///< the reference point in the body frame, c0
  double rot[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< rotation body -> world (row major)
  double omega[3] = {0, 0, 0};   ///< angular velocity
  double vlin[3] = {0, 0, 0};    ///< linear velocity of c(t)
  double thickness = 0;
};

namespace mesh_detail {
LOOM_HD inline double dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
LOOM_HD inline void sub3(const double* a, const double* b, double* r) {
  r[0] = a[0] - b[0];
  r[1] = a[1] - b[1];
  r[2] = a[2] - b[2];
}
LOOM_HD inline void copy3(const double* a, double* r) {
  r[0] = a[0];
  r[1] = a[1];
  r[2] = a[2];
}
}  // namespace mesh_detail

/// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5), with
/// the feature it lies on: 0..2 vertex k, 3..5 edge (k, k+1) for k = feature - 3, 6 interior.
LOOM_HD inline int closest_on_triangle(const double* p, const double* a, const double* b, const double* c, double* q) {
  using namespace mesh_detail;
  double ab[3], ac[3], ap[3];
  sub3(b, a, ab);
  sub3(c, a, ac);
  sub3(p, a, ap);
  const double d1 = dot3(ab, ap), d2 = dot3(ac, ap);
  if (d1 <= 0 && d2 <= 0) {
    copy3(a, q);
    return 0;
  }
  double bp[3];
  sub3(p, b, bp);
  const double d3 = dot3(ab, bp), d4 = dot3(ac, bp);
  if (d3 >= 0 && d4 <= d3) {
    copy3(b, q);
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
    copy3(c, q);
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

LOOM_HD inline double box_distance2(const double* lo, const double* hi, const double* p) {
  double d2 = 0;
  for (int k = 0; k < 3; ++k) {
    const double d = p[k] < lo[k] ? lo[k] - p[k] : (p[k] > hi[k] ? p[k] - hi[k] : 0.0);
    d2 += d * d;
  }
  return d2;
}

/// Depth of the traversal stack: the hierarchy's depth is ~log2(faces / 4) + 1.
constexpr int kMeshStackDepth = 128;

/// Nearest point among the faces closer than sqrt(limit2) (all faces for INFINITY); false if none.
LOOM_HD LOOM_MESH_NOINLINE inline bool mesh_nearest_within(const MeshView& m, const double p[3], double limit2, MeshNearest& best) {
  using namespace mesh_detail;
  double best_d2 = limit2;
  int best_feature = -1;
  Index stack[kMeshStackDepth];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const MeshNode& nd = m.nodes[stack[--top]];
    if (box_distance2(nd.lo, nd.hi, p) >= best_d2) continue;
    if (nd.count > 0) {
      for (Index i = nd.first; i < nd.first + nd.count; ++i) {
        const Index t = m.order[i];
        const Index* T = m.tri + 3LL * t;
        double q[3];
        const int f = closest_on_triangle(p, m.x + 3LL * T[0], m.x + 3LL * T[1], m.x + 3LL * T[2], q);
        double d[3];
        sub3(p, q, d);
        const double d2 = dot3(d, d);
        if (d2 < best_d2) {
          best_d2 = d2;
          best_feature = f;
          best.face = t;
          copy3(q, best.point);
        }
      }
      continue;
    }
    // Visit the nearer child first (pushed last).
    const MeshNode& l = m.nodes[nd.first];
    const MeshNode& r = m.nodes[nd.right];
    const double dl = box_distance2(l.lo, l.hi, p), dr = box_distance2(r.lo, r.hi, p);
    if (top + 2 > kMeshStackDepth) continue;  // never reached for any real mesh
    if (dl < dr) {
      stack[top++] = nd.right;
      stack[top++] = nd.first;
    } else {
      stack[top++] = nd.first;
      stack[top++] = nd.right;
    }
  }
  if (best_feature < 0) return false;
  using std::sqrt;
  best.distance = sqrt(best_d2);
  const double* n = best_feature < 3   ? m.vert_n + 3LL * m.tri[3LL * best.face + best_feature]
                    : best_feature < 6 ? m.edge_n + 9LL * best.face + 3 * (best_feature - 3)
                                       : m.face_n + 3LL * best.face;
  copy3(n, best.normal);
  return true;
}

/// Signed distance from a nearest feature: the sign from its pseudo-normal; the contact normal
/// is the direction to the point (flipped inside), except on the surface itself, where the
/// pseudo-normal is.
LOOM_HD inline double mesh_signed_from(const double p[3], const MeshNearest& nr, double normal[3], double point[3]) {
  using namespace mesh_detail;
  double d[3];
  sub3(p, nr.point, d);
  const double s = dot3(d, nr.normal) < 0 ? -1.0 : 1.0;
  copy3(nr.point, point);
  if (nr.distance > 1e-12) {
    for (int k = 0; k < 3; ++k) normal[k] = s * d[k] / nr.distance;
  } else {
    copy3(nr.normal, normal);
  }
  return s * nr.distance;
}

/// Signed distance (< 0 inside / behind), outward unit normal and nearest point at p (body
/// frame), for callers that need the answer only below `cutoff` (> 0; INFINITY: everywhere):
/// a result below cutoff is exact; a result >= cutoff is a lower bound of a positive distance
/// (normal and point then unspecified). On a closed mesh a point outside the root box by
/// cutoff or more is answered from the box alone.
LOOM_HD inline double mesh_signed_distance(const MeshView& m, const double p[3], double normal[3], double point[3],
                                           double cutoff) {
  const MeshNode& root = m.nodes[0];
  const double box2 = box_distance2(root.lo, root.hi, p);
  MeshNearest nr{};
  if (m.closed && box2 > 0) {
    // Outside the box of a closed mesh is outside the body: farther than the box distance.
    using std::sqrt;
    double bound = 0;
    if (box2 >= cutoff * cutoff) {
      bound = sqrt(box2);
    } else if (!mesh_nearest_within(m, p, cutoff * cutoff, nr)) {
      bound = cutoff;
    } else {
      return mesh_signed_from(p, nr, normal, point);
    }
    for (int k = 0; k < 3; ++k) normal[k] = 0, point[k] = p[k];
    return bound;
  }
  // Inside the box (or an open mesh, whose back side counts as inside): the sign needs the
  // nearest face wherever it is.
  if (!mesh_nearest_within(m, p, cutoff * cutoff, nr)) mesh_nearest_within(m, p, INFINITY, nr);
  return mesh_signed_from(p, nr, normal, point);
}

/// The mesh collider's contact query at world point x: signed distance to the offset surface
/// (distance - thickness; < 0 inside), outward unit normal n and the surface velocity vs at the
/// nearest point. `cutoff` (>= 0, or INFINITY) as for Collider::query: exact below it.
LOOM_HD LOOM_MESH_NOINLINE inline double mesh_contact_query(const MeshView& m, const MeshPlacement& f, const double x[3], double cutoff,
                                         double n[3], double vs[3]) {
  // Into the body frame: y = R^T (x - c(t)) + c0; the answer back: R n, R (q - c0) + c(t).
  const double r[3] = {x[0] - f.center[0], x[1] - f.center[1], x[2] - f.center[2]};
  const double* R = f.rot;
  const double y[3] = {R[0] * r[0] + R[3] * r[1] + R[6] * r[2] + f.pivot[0],
                       R[1] * r[0] + R[4] * r[1] + R[7] * r[2] + f.pivot[1],
                       R[2] * r[0] + R[5] * r[1] + R[8] * r[2] + f.pivot[2]};
  double nb[3], qb[3];
  const double sd = mesh_signed_distance(m, y, nb, qb, cutoff + f.thickness);
  const double q[3] = {qb[0] - f.pivot[0], qb[1] - f.pivot[1], qb[2] - f.pivot[2]};
  n[0] = R[0] * nb[0] + R[1] * nb[1] + R[2] * nb[2];
  n[1] = R[3] * nb[0] + R[4] * nb[1] + R[5] * nb[2];
  n[2] = R[6] * nb[0] + R[7] * nb[1] + R[8] * nb[2];
  const double arm[3] = {R[0] * q[0] + R[1] * q[1] + R[2] * q[2], R[3] * q[0] + R[4] * q[1] + R[5] * q[2],
                         R[6] * q[0] + R[7] * q[1] + R[8] * q[2]};
  const double w[3] = {f.omega[1] * arm[2] - f.omega[2] * arm[1], f.omega[2] * arm[0] - f.omega[0] * arm[2],
                       f.omega[0] * arm[1] - f.omega[1] * arm[0]};
  for (int k = 0; k < 3; ++k) vs[k] = f.vlin[k] + w[k];
  return sd - f.thickness;
}

}  // namespace loom::kernels
