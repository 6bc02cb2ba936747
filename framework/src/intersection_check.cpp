// Exact triangle-triangle intersection check (see intersection_check.hpp for what counts).
//
// Predicates: orient3d / orient2d with a floating-point filter and an exact fallback in
// expansion arithmetic (nonoverlapping sums of doubles; Shewchuk 1997, "Adaptive precision
// floating-point arithmetic and fast robust geometric predicates"). This file is compiled
// with -ffp-contract=off (framework/CMakeLists.txt): the error-free transformations need
// each product and sum rounded on its own.
//
// Test: two closed triangles A and B intersect iff an edge of A meets B or an edge of B
// meets A. (The intersection, when not empty, is compact and convex; an extreme point of it
// lies on the relative boundary of A or of B, that is on an edge.) A degenerate triangle is
// the union of its edges, so the same holds with its edges only. Segment-triangle: the
// segment's end points against the triangle's plane (orient3d); a segment crossing or
// touching the plane hits the closed triangle iff the three orient3d of the line against
// the triangle's edges do not take both signs; a segment in the plane is tested in an axis
// projection on which the plane projects one-to-one (the one where the triangle's orient2d
// is not zero): an end point in the triangle, or a crossing with one of its edges.
#include "loom/intersection_check.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>

namespace loom {

namespace {

// ---- error-free transformations and expansion arithmetic -------------------------------

inline void two_sum(double a, double b, double& x, double& y) {
  x = a + b;
  const double bv = x - a;
  const double av = x - bv;
  y = (a - av) + (b - bv);
}

inline void two_diff(double a, double b, double& x, double& y) {
  x = a - b;
  const double bv = a - x;
  const double av = x + bv;
  y = (a - av) + (bv - b);
}

inline void fast_two_sum(double a, double b, double& x, double& y) {  // |a| >= |b|
  x = a + b;
  y = b - (x - a);
}

inline void two_product(double a, double b, double& x, double& y) {
  x = a * b;
  y = std::fma(a, b, -x);
}

// h = e + b (e nonoverlapping, increasing magnitude; h may alias e). Returns h's length.
int grow(const double* e, int n, double b, double* h) {
  double q = b;
  int k = 0;
  for (int i = 0; i < n; ++i) {
    double qn, hh;
    two_sum(q, e[i], qn, hh);
    q = qn;
    if (hh != 0) h[k++] = hh;
  }
  if (q != 0 || k == 0) h[k++] = q;
  return k;
}

// h = e + f, in place on h's buffer (h must hold ne + nf; h may alias e).
int sum(const double* e, int ne, const double* f, int nf, double* h) {
  if (h != e) std::copy(e, e + ne, h);
  int n = ne;
  for (int i = 0; i < nf; ++i) n = grow(h, n, f[i], h);
  return n;
}

// h = b * e (h must not alias e; it holds 2 ne).
int scale(const double* e, int n, double b, double* h) {
  double q, hh;
  int k = 0;
  two_product(e[0], b, q, hh);
  if (hh != 0) h[k++] = hh;
  for (int i = 1; i < n; ++i) {
    double p1, p0, s;
    two_product(e[i], b, p1, p0);
    two_sum(q, p0, s, hh);
    if (hh != 0) h[k++] = hh;
    fast_two_sum(p1, s, q, hh);
    if (hh != 0) h[k++] = hh;
  }
  if (q != 0 || k == 0) h[k++] = q;
  return k;
}

constexpr int kMaxTerms = 256;

// h = e * f (h holds 2 ne nf, distinct from e and f).
int mul(const double* e, int ne, const double* f, int nf, double* h) {
  double tmp[kMaxTerms];
  int n = 0;
  for (int i = 0; i < nf; ++i) {
    const int t = scale(e, ne, f[i], tmp);
    n = n == 0 ? (std::copy(tmp, tmp + t, h), t) : sum(h, n, tmp, t, h);
  }
  return n;
}

int negate(double* e, int n) {
  for (int i = 0; i < n; ++i) e[i] = -e[i];
  return n;
}

int sign_of(const double* e, int n) {
  const double top = e[n - 1];  // the largest-magnitude component decides
  return top > 0 ? 1 : (top < 0 ? -1 : 0);
}

struct Two {
  double c[2];
  int n;
};

Two diff2(double a, double b) {
  Two t;
  double x, y;
  two_diff(a, b, x, y);
  if (y != 0) {
    t.c[0] = y;
    t.c[1] = x;
    t.n = 2;
  } else {
    t.c[0] = x;
    t.n = 1;
  }
  return t;
}

// Exact sign of p*q - r*s for 2-expansions.
int cross_term(const Two& p, const Two& q, const Two& r, const Two& s, double* out) {
  double a[8], b[8];
  const int na = mul(p.c, p.n, q.c, q.n, a);
  const int nb = negate(b, mul(r.c, r.n, s.c, s.n, b));
  return sum(a, na, b, nb, out);
}

int orient3d_exact(const double* a, const double* b, const double* c, const double* d) {
  const Two ux = diff2(b[0], a[0]), uy = diff2(b[1], a[1]), uz = diff2(b[2], a[2]);
  const Two vx = diff2(c[0], a[0]), vy = diff2(c[1], a[1]), vz = diff2(c[2], a[2]);
  const Two wx = diff2(d[0], a[0]), wy = diff2(d[1], a[1]), wz = diff2(d[2], a[2]);
  double m1[16], m2[16], m3[16];
  const int n1 = cross_term(vy, wz, vz, wy, m1);
  const int n2 = cross_term(vz, wx, vx, wz, m2);
  const int n3 = cross_term(vx, wy, vy, wx, m3);
  double t1[64], t2[64], t3[64], acc[kMaxTerms];
  const int k1 = mul(m1, n1, ux.c, ux.n, t1);
  const int k2 = mul(m2, n2, uy.c, uy.n, t2);
  const int k3 = mul(m3, n3, uz.c, uz.n, t3);
  int n = sum(t1, k1, t2, k2, acc);
  n = sum(acc, n, t3, k3, acc);
  return sign_of(acc, n);
}

int orient2d_exact(const double* a, const double* b, const double* c, int u, int v) {
  const Two bu = diff2(b[u], a[u]), bv = diff2(b[v], a[v]);
  const Two cu = diff2(c[u], a[u]), cv = diff2(c[v], a[v]);
  double out[16];
  const int n = cross_term(bu, cv, bv, cu, out);
  return sign_of(out, n);
}

// Forward error bounds of the double evaluations below, relative to the permanent (Shewchuk's
// o3derrboundA = 7.8e-16 and ccwerrboundA = 3.3e-16, rounded up generously).
constexpr double kOrient3dBound = 1.0e-15;
constexpr double kOrient2dBound = 1.0e-15;

}  // namespace

namespace exact {

int orient3d(const double* a, const double* b, const double* c, const double* d) {
  const double ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
  const double vx = c[0] - a[0], vy = c[1] - a[1], vz = c[2] - a[2];
  const double wx = d[0] - a[0], wy = d[1] - a[1], wz = d[2] - a[2];
  const double p1 = vy * wz, p2 = vz * wy, p3 = vz * wx, p4 = vx * wz, p5 = vx * wy, p6 = vy * wx;
  const double det = ux * (p1 - p2) + uy * (p3 - p4) + uz * (p5 - p6);
  const double perm = std::fabs(ux) * (std::fabs(p1) + std::fabs(p2)) + std::fabs(uy) * (std::fabs(p3) + std::fabs(p4)) +
                      std::fabs(uz) * (std::fabs(p5) + std::fabs(p6));
  const double bound = kOrient3dBound * perm;
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return orient3d_exact(a, b, c, d);
}

int orient2d(const double* a, const double* b, const double* c, int u, int v) {
  const double l = (b[u] - a[u]) * (c[v] - a[v]);
  const double r = (b[v] - a[v]) * (c[u] - a[u]);
  const double det = l - r;
  const double bound = kOrient2dBound * (std::fabs(l) + std::fabs(r));
  if (det > bound) return 1;
  if (-det > bound) return -1;
  return orient2d_exact(a, b, c, u, v);
}

}  // namespace exact

namespace {

using exact::orient2d;
using exact::orient3d;

// Axis projections (u, v) dropping coordinate 2, 0, 1.
constexpr int kProj[3][2] = {{0, 1}, {1, 2}, {2, 0}};

// Collinear r on the closed segment pq (coordinates u, v)?
bool on_segment_2d(const double* p, const double* q, const double* r, int u, int v) {
  return std::min(p[u], q[u]) <= r[u] && r[u] <= std::max(p[u], q[u]) && std::min(p[v], q[v]) <= r[v] &&
         r[v] <= std::max(p[v], q[v]);
}

// Closed segments pq and rs in the (u, v) projection.
bool segments_2d(const double* p, const double* q, const double* r, const double* s, int u, int v) {
  const int o1 = orient2d(p, q, r, u, v), o2 = orient2d(p, q, s, u, v);
  const int o3 = orient2d(r, s, p, u, v), o4 = orient2d(r, s, q, u, v);
  if (o1 * o2 < 0 && o3 * o4 < 0) return true;
  return (o1 == 0 && on_segment_2d(p, q, r, u, v)) || (o2 == 0 && on_segment_2d(p, q, s, u, v)) ||
         (o3 == 0 && on_segment_2d(r, s, p, u, v)) || (o4 == 0 && on_segment_2d(r, s, q, u, v));
}

// Point p in the closed triangle abc of orientation o != 0 in the (u, v) projection.
bool point_in_triangle_2d(const double* p, const double* a, const double* b, const double* c, int o, int u, int v) {
  const int s1 = orient2d(a, b, p, u, v), s2 = orient2d(b, c, p, u, v), s3 = orient2d(c, a, p, u, v);
  return (s1 == 0 || s1 == o) && (s2 == 0 || s2 == o) && (s3 == 0 || s3 == o);
}

// A non-degenerate triangle with a projection on which its plane maps one-to-one.
struct Tri {
  const double* v[3];
  int u = 0, w = 1;   // projection axes
  int o = 0;          // orientation in that projection (0: degenerate triangle)
};

Tri make_tri(const double* a, const double* b, const double* c) {
  Tri t;
  t.v[0] = a;
  t.v[1] = b;
  t.v[2] = c;
  for (const auto& pr : kProj) {
    const int o = orient2d(a, b, c, pr[0], pr[1]);
    if (o != 0) {
      t.u = pr[0];
      t.w = pr[1];
      t.o = o;
      break;
    }
  }
  return t;
}

// Closed segment pq against a non-degenerate closed triangle.
bool segment_triangle(const double* p, const double* q, const Tri& t) {
  const double *a = t.v[0], *b = t.v[1], *c = t.v[2];
  const int op = orient3d(a, b, c, p), oq = orient3d(a, b, c, q);
  if (op * oq > 0) return false;
  if (op == 0 && oq == 0) {  // in the triangle's plane
    return point_in_triangle_2d(p, a, b, c, t.o, t.u, t.w) || point_in_triangle_2d(q, a, b, c, t.o, t.u, t.w) ||
           segments_2d(p, q, a, b, t.u, t.w) || segments_2d(p, q, b, c, t.u, t.w) || segments_2d(p, q, c, a, t.u, t.w);
  }
  // The segment meets the plane in one point: the line through it must pass the closed triangle.
  const int s1 = orient3d(p, q, a, b), s2 = orient3d(p, q, b, c), s3 = orient3d(p, q, c, a);
  const bool pos = s1 > 0 || s2 > 0 || s3 > 0, neg = s1 < 0 || s2 < 0 || s3 < 0;
  return !(pos && neg);
}

// Closed segments in 3D: coplanar (exact orient3d == 0) and overlapping in every axis
// projection (exact: one of them maps their common plane one-to-one; the others can only
// add intersections, never remove one).
bool segments_3d(const double* p, const double* q, const double* r, const double* s) {
  if (orient3d(p, q, r, s) != 0) return false;
  for (const auto& pr : kProj)
    if (!segments_2d(p, q, r, s, pr[0], pr[1])) return false;
  return true;
}

// Every vertex of one triangle strictly on one side of the other's plane?
bool separated_by_plane(const double* a0, const double* a1, const double* a2, const double* b0, const double* b1,
                        const double* b2) {
  const int s0 = orient3d(a0, a1, a2, b0), s1 = orient3d(a0, a1, a2, b1), s2 = orient3d(a0, a1, a2, b2);
  return (s0 > 0 && s1 > 0 && s2 > 0) || (s0 < 0 && s1 < 0 && s2 < 0);
}

}  // namespace

bool triangles_intersect(const double* a0, const double* a1, const double* a2, const double* b0, const double* b1,
                         const double* b2) {
  if (separated_by_plane(a0, a1, a2, b0, b1, b2) || separated_by_plane(b0, b1, b2, a0, a1, a2)) return false;
  const Tri A = make_tri(a0, a1, a2), B = make_tri(b0, b1, b2);
  const double* ea[3][2] = {{a0, a1}, {a1, a2}, {a2, a0}};
  const double* eb[3][2] = {{b0, b1}, {b1, b2}, {b2, b0}};
  if (A.o != 0 && B.o != 0) {
    for (const auto& e : ea)
      if (segment_triangle(e[0], e[1], B)) return true;
    for (const auto& e : eb)
      if (segment_triangle(e[0], e[1], A)) return true;
    return false;
  }
  if (B.o != 0) {  // A is a segment or a point: the union of its edges
    for (const auto& e : ea)
      if (segment_triangle(e[0], e[1], B)) return true;
    return false;
  }
  if (A.o != 0) {
    for (const auto& e : eb)
      if (segment_triangle(e[0], e[1], A)) return true;
    return false;
  }
  for (const auto& e : ea)
    for (const auto& f : eb)
      if (segments_3d(e[0], e[1], f[0], f[1])) return true;
  return false;
}

namespace {

// The positions to use (x, or the mesh's own when x is empty), checked: one per vertex, finite.
const double* checked_positions(const Mesh& mesh, std::span<const double> xs, const char* who) {
  const double* x = xs.empty() ? mesh.positions.data() : xs.data();
  const std::size_t nx = xs.empty() ? mesh.positions.size() : xs.size();
  if (nx != 3 * static_cast<std::size_t>(mesh.num_vertices()))
    throw InputError(std::string(who) + ": " + std::to_string(nx / 3) + " positions for a mesh of " +
                     std::to_string(mesh.num_vertices()) + " vertices");
  for (std::size_t k = 0; k < nx; ++k)
    if (!std::isfinite(x[k]))
      throw InputError(std::string(who) + ": vertex " + std::to_string(k / 3) +
                       " has a NaN or Inf coordinate: the answer is undefined");
  return x;
}

// The broad phase of both checks: pair(local, ti, tj, lo, hi) is called once for every pair of
// triangles whose bounding boxes, grown by `grow` on every side, overlap (closed), on OpenMP
// threads, each with its own copy `local` of `init`; join(local) then receives the copies one
// at a time. lo, hi: the boxes (3 per triangle, not grown). A uniform grid over the grown boxes,
// cells about the mean triangle size (at least 2 grow), at most ~4 cells per triangle; each
// pair is visited in the cell that holds the lower corner of the boxes' overlap.
template <class Local, class Pair, class Join>
void for_each_box_pair(const Mesh& mesh, const double* x, double grow, const Local& init, Pair&& pair, Join&& join) {
  const Index nt = mesh.num_triangles();
  if (nt < 2) return;
  const Index* T = mesh.triangles.data();
  std::vector<double> lo(3 * static_cast<std::size_t>(nt)), hi(3 * static_cast<std::size_t>(nt));
  double glo[3] = {INFINITY, INFINITY, INFINITY}, ghi[3] = {-INFINITY, -INFINITY, -INFINITY};
  double mean_size = 0;
  for (Index t = 0; t < nt; ++t) {
    double size = 0;
    for (int k = 0; k < 3; ++k) {
      const double p = x[3 * T[3 * t] + k], q = x[3 * T[3 * t + 1] + k], r = x[3 * T[3 * t + 2] + k];
      const double l = std::min({p, q, r}), h = std::max({p, q, r});
      lo[3 * t + k] = l;
      hi[3 * t + k] = h;
      glo[k] = std::min(glo[k], l - grow);
      ghi[k] = std::max(ghi[k], h + grow);
      size = std::max(size, h - l + 2 * grow);
    }
    mean_size += size / nt;
  }
  double extent = 0;
  for (int k = 0; k < 3; ++k) extent = std::max(extent, ghi[k] - glo[k]);
  double cell = mean_size > 0 ? mean_size : (extent > 0 ? extent : 1.0);
  std::int64_t dims[3];
  const std::int64_t max_cells = 4 * static_cast<std::int64_t>(nt) + 64;
  for (;;) {
    std::int64_t total = 1;
    for (int k = 0; k < 3; ++k) {
      dims[k] = std::max<std::int64_t>(1, static_cast<std::int64_t>((ghi[k] - glo[k]) / cell) + 1);
      total *= dims[k];
    }
    if (total <= max_cells) break;
    cell *= 1.5;
  }
  auto cell_of = [&](double c, int k) {
    const auto i = static_cast<std::int64_t>((c - glo[k]) / cell);
    return std::clamp<std::int64_t>(i, 0, dims[k] - 1);
  };
  const std::int64_t ncell = dims[0] * dims[1] * dims[2];
  auto flat = [&](std::int64_t i, std::int64_t j, std::int64_t k) { return (k * dims[1] + j) * dims[0] + i; };

  std::vector<std::int64_t> start(ncell + 1, 0);
  auto for_cells = [&](Index t, auto&& fn) {
    const std::int64_t i0 = cell_of(lo[3 * t] - grow, 0), i1 = cell_of(hi[3 * t] + grow, 0);
    const std::int64_t j0 = cell_of(lo[3 * t + 1] - grow, 1), j1 = cell_of(hi[3 * t + 1] + grow, 1);
    const std::int64_t k0 = cell_of(lo[3 * t + 2] - grow, 2), k1 = cell_of(hi[3 * t + 2] + grow, 2);
    for (std::int64_t k = k0; k <= k1; ++k)
      for (std::int64_t j = j0; j <= j1; ++j)
        for (std::int64_t i = i0; i <= i1; ++i) fn(flat(i, j, k));
  };
  for (Index t = 0; t < nt; ++t) for_cells(t, [&](std::int64_t c) { ++start[c + 1]; });
  for (std::int64_t c = 0; c < ncell; ++c) start[c + 1] += start[c];
  std::vector<Index> items(static_cast<std::size_t>(start[ncell]));
  {
    std::vector<std::int64_t> fill(start.begin(), start.end() - 1);
    for (Index t = 0; t < nt; ++t) for_cells(t, [&](std::int64_t c) { items[fill[c]++] = t; });
  }

#pragma omp parallel
  {
    Local mine = init;
#pragma omp for schedule(dynamic, 64)
    for (std::int64_t c = 0; c < ncell; ++c) {
      for (std::int64_t a = start[c]; a < start[c + 1]; ++a) {
        const Index ti = items[a];
        for (std::int64_t b = a + 1; b < start[c + 1]; ++b) {
          const Index tj = items[b];
          // Grown boxes overlap (closed)?
          double m[3];
          bool overlap = true;
          for (int k = 0; k < 3 && overlap; ++k) {
            overlap = lo[3 * ti + k] - grow <= hi[3 * tj + k] + grow && lo[3 * tj + k] - grow <= hi[3 * ti + k] + grow;
            m[k] = std::max(lo[3 * ti + k], lo[3 * tj + k]) - grow;
          }
          if (!overlap) continue;
          // Visit each pair once: in the cell holding the lower corner of the grown boxes' overlap.
          if (flat(cell_of(m[0], 0), cell_of(m[1], 1), cell_of(m[2], 2)) != c) continue;
          pair(mine, ti, tj, lo.data(), hi.data());
        }
      }
    }
#pragma omp critical
    join(mine);
  }
}

bool share_vertex(const Index* A, const Index* B) {
  for (int p = 0; p < 3; ++p)
    for (int q = 0; q < 3; ++q)
      if (A[p] == B[q]) return true;
  return false;
}

}  // namespace

std::size_t count_intersecting_pairs(const Mesh& mesh, std::span<const double> xs,
                                     std::vector<std::array<Index, 2>>* pairs) {
  const double* x = checked_positions(mesh, xs, "count_intersecting_pairs");
  if (pairs) pairs->clear();
  const Index* T = mesh.triangles.data();
  std::vector<std::array<Index, 2>> found;
  for_each_box_pair(
      mesh, x, 0.0, std::vector<std::array<Index, 2>>(),
      [&](std::vector<std::array<Index, 2>>& mine, Index ti, Index tj, const double*, const double*) {
        const Index* A = T + 3 * ti;
        const Index* B = T + 3 * tj;
        if (share_vertex(A, B)) return;
        if (triangles_intersect(x + 3 * A[0], x + 3 * A[1], x + 3 * A[2], x + 3 * B[0], x + 3 * B[1], x + 3 * B[2]))
          mine.push_back({std::min(ti, tj), std::max(ti, tj)});
      },
      [&](const std::vector<std::array<Index, 2>>& mine) { found.insert(found.end(), mine.begin(), mine.end()); });
  std::sort(found.begin(), found.end());
  const std::size_t count = found.size();
  if (pairs) *pairs = std::move(found);
  return count;
}

// ---- closest approach ----

namespace distance {

namespace {
inline double dot(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline void sub(const double* a, const double* b, double* r) {
  r[0] = a[0] - b[0];
  r[1] = a[1] - b[1];
  r[2] = a[2] - b[2];
}
// Lexicographic order of points: the distance functions sort their arguments by it, so that
// their result does not depend on the order of the vertices or of the two elements (bit for bit).
inline bool before(const double* a, const double* b) {
  return a[0] != b[0] ? a[0] < b[0] : a[1] != b[1] ? a[1] < b[1] : a[2] < b[2];
}
inline double dist_to(const double* p, const double* q0, const double* d, double t) {
  const double c[3] = {q0[0] + t * d[0] - p[0], q0[1] + t * d[1] - p[1], q0[2] + t * d[2] - p[2]};
  return std::sqrt(dot(c, c));
}
}  // namespace

double point_segment(const double* p, const double* a, const double* b) {
  if (before(b, a)) std::swap(a, b);
  double d[3], ap[3];
  sub(b, a, d);
  sub(p, a, ap);
  const double dd = dot(d, d);
  const double t = dd > 0 ? std::clamp(dot(ap, d) / dd, 0.0, 1.0) : 0.0;
  return dist_to(p, a, d, t);
}

// The closest point by the triangle's Voronoi regions (vertices, edges, face); every candidate is
// a point of the triangle, so each distance is at least the true one, and the minimum with the
// three edges' distances is the true one also when the triangle is degenerate (a segment or a
// point), where the face region's barycentric division is 0 / 0.
double point_triangle(const double* p, const double* a, const double* b, const double* c) {
  if (before(b, a)) std::swap(a, b);
  if (before(c, b)) std::swap(b, c);
  if (before(b, a)) std::swap(a, b);
  const double edges = std::min({point_segment(p, a, b), point_segment(p, b, c), point_segment(p, c, a)});
  double ab[3], ac[3], ap[3];
  sub(b, a, ab);
  sub(c, a, ac);
  sub(p, a, ap);
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  double bp[3], cp[3];
  sub(p, b, bp);
  sub(p, c, cp);
  const double d3 = dot(ab, bp), d4 = dot(ac, bp), d5 = dot(ab, cp), d6 = dot(ac, cp);
  const double va = d3 * d6 - d5 * d4, vb = d5 * d2 - d1 * d6, vc = d1 * d4 - d3 * d2;
  // Outside the face region (some barycentric negative): the closest point is on an edge or a vertex.
  if (va < 0 || vb < 0 || vc < 0) return edges;
  const double den = va + vb + vc;
  if (!(den > 0)) return edges;
  const double v = vb / den, w = vc / den;
  const double q[3] = {a[0] + v * ab[0] + w * ac[0] - p[0], a[1] + v * ab[1] + w * ac[1] - p[1],
                       a[2] + v * ab[2] + w * ac[2] - p[2]};
  return std::min(edges, std::sqrt(dot(q, q)));
}

// The interior stationary point of |p0 + s d0 - q0 - t d1| when the segments are not parallel,
// clamped (each clamp keeps a point of both segments), and the four endpoint-to-segment
// distances: every candidate is a distance between points of the two segments, and the true
// minimum is one of them (interior-interior for crossing directions, else an endpoint), also
// when the segments are parallel or degenerate.
double segment_segment(const double* p0, const double* p1, const double* q0, const double* q1) {
  if (before(p1, p0)) std::swap(p0, p1);
  if (before(q1, q0)) std::swap(q0, q1);
  if (before(q0, p0) || (!before(p0, q0) && before(q1, p1))) {
    std::swap(p0, q0);
    std::swap(p1, q1);
  }
  double best = std::min({point_segment(p0, q0, q1), point_segment(p1, q0, q1), point_segment(q0, p0, p1),
                          point_segment(q1, p0, p1)});
  double d0[3], d1[3], r[3];
  sub(p1, p0, d0);
  sub(q1, q0, d1);
  sub(p0, q0, r);
  const double a = dot(d0, d0), e = dot(d1, d1), b = dot(d0, d1), c = dot(d0, r), f = dot(d1, r);
  const double den = a * e - b * b;
  if (a > 0 && e > 0 && den > 1e-12 * a * e) {
    const double s = std::clamp((b * f - c * e) / den, 0.0, 1.0);
    const double t = std::clamp((b * s + f) / e, 0.0, 1.0);
    const double g[3] = {p0[0] + s * d0[0] - q0[0] - t * d1[0], p0[1] + s * d0[1] - q0[1] - t * d1[1],
                         p0[2] + s * d0[2] - q0[2] - t * d1[2]};
    best = std::min(best, std::sqrt(dot(g, g)));
  }
  return best;
}

}  // namespace distance

namespace {

// Candidate (distance, kind, indices) ordered so that equal distances pick the same pair on any
// thread count: vertex-triangle before edge-edge, then by indices.
bool closer(const ClosestApproach& a, const ClosestApproach& b) {
  if (a.distance != b.distance) return a.distance < b.distance;
  if (a.vertex_triangle != b.vertex_triangle) return a.vertex_triangle;
  return a.v < b.v;
}

}  // namespace

ClosestApproach closest_approach(const Mesh& mesh, std::span<const double> xs, double within) {
  const double* x = checked_positions(mesh, xs, "closest_approach");
  if (!(within > 0) || !std::isfinite(within))
    throw InputError("closest_approach: the search distance must be finite and > 0");
  const Index* T = mesh.triangles.data();
  ClosestApproach best;
  best.distance = within;  // pairs at `within` or farther are not looked for
  auto consider = [](ClosestApproach& mine, double d, bool vt, std::array<Index, 4> v) {
    ClosestApproach c;
    c.distance = d;
    c.vertex_triangle = vt;
    c.v = v;
    if (closer(c, mine)) mine = c;
  };
  for_each_box_pair(
      mesh, x, 0.5 * within, best,
      [&](ClosestApproach& mine, Index ti, Index tj, const double* lo, const double* hi) {
        // No element pair of the two triangles is closer than their boxes' gap (in any norm).
        double gap = 0;
        for (int k = 0; k < 3; ++k)
          gap = std::max({gap, lo[3 * ti + k] - hi[3 * tj + k], lo[3 * tj + k] - hi[3 * ti + k]});
        if (gap > mine.distance) return;
        const Index* A = T + 3 * ti;
        const Index* B = T + 3 * tj;
        auto P = [&](Index v) { return x + 3 * static_cast<std::size_t>(v); };
        auto in = [](Index v, const Index* t) { return v == t[0] || v == t[1] || v == t[2]; };
        for (int side = 0; side < 2; ++side) {
          const Index* U = side ? B : A;
          const Index* V = side ? A : B;
          for (int k = 0; k < 3; ++k)
            if (!in(U[k], V))
              consider(mine, distance::point_triangle(P(U[k]), P(V[0]), P(V[1]), P(V[2])), true,
                       {U[k], V[0], V[1], V[2]});
        }
        for (int i = 0; i < 3; ++i) {
          const Index a0 = A[i], a1 = A[(i + 1) % 3];
          for (int j = 0; j < 3; ++j) {
            const Index b0 = B[j], b1 = B[(j + 1) % 3];
            if (a0 == b0 || a0 == b1 || a1 == b0 || a1 == b1) continue;
            consider(mine, distance::segment_segment(P(a0), P(a1), P(b0), P(b1)), false,
                     {std::min(a0, a1), std::max(a0, a1), std::min(b0, b1), std::max(b0, b1)});
          }
        }
      },
      [&](const ClosestApproach& mine) {
        if (closer(mine, best)) best = mine;
      });
  if (!(best.distance < within)) return ClosestApproach{};
  if (!best.vertex_triangle && best.v[2] < best.v[0]) {  // the edge pair in a fixed order
    std::swap(best.v[0], best.v[2]);
    std::swap(best.v[1], best.v[3]);
  }
  return best;
}

}  // namespace loom
