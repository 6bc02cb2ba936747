#include "loom/self_collision.hpp"
#include "loom/rotation.hpp"
#include "loom/intersection_check.hpp"

#include "loom/collider.hpp"
#include "loom/kernels/contact.hpp"
#include "loom/clock.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <numeric>
#include <sstream>

#include <omp.h>

namespace loom {

namespace selfcol {

namespace {

inline void sub(const double* a, const double* b, double* r) {
  r[0] = a[0] - b[0];
  r[1] = a[1] - b[1];
  r[2] = a[2] - b[2];
}
inline double dot(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline void cross(const double* a, const double* b, double* r) {
  r[0] = a[1] * b[2] - a[2] * b[1];
  r[1] = a[2] * b[0] - a[0] * b[2];
  r[2] = a[0] * b[1] - a[1] * b[0];
}
inline double clamp01(double v) { return v < 0 ? 0 : (v > 1 ? 1 : v); }

// Closest point on segment (a, b) to p: parameter in [0, 1].
double point_segment_param(const double* p, const double* a, const double* b) {
  double ab[3], ap[3];
  sub(b, a, ab);
  sub(p, a, ap);
  const double l2 = dot(ab, ab);
  return l2 > 0 ? clamp01(dot(ap, ab) / l2) : 0.0;
}

// Coefficients of the coplanarity polynomial (u x w) . r with u = u0 + t du, etc.
void coplanarity_cubic(const double* u0, const double* du, const double* w0, const double* dw, const double* r0,
                       const double* dr, double c[4]) {
  double a[3], b1[3], b2[3], e[3];
  cross(u0, w0, a);
  cross(u0, dw, b1);
  cross(du, w0, b2);
  const double b[3] = {b1[0] + b2[0], b1[1] + b2[1], b1[2] + b2[2]};
  cross(du, dw, e);
  c[0] = dot(a, r0);
  c[1] = dot(a, dr) + dot(b, r0);
  c[2] = dot(b, dr) + dot(e, r0);
  c[3] = dot(e, dr);
}

template <class Dist>
bool first_contact(const double c[4], double tol, Dist&& dist, double& t_out) {
  double ts[7];
  const int k = cubic_candidate_times(c[0], c[1], c[2], c[3], ts);
  for (int i = 0; i < k; ++i)
    if (dist(ts[i]) <= tol) {
      t_out = ts[i];
      return true;
    }
  return false;
}

void lerp4(const double x0[4][3], const double x1[4][3], double t, double out[4][3]) {
  for (int i = 0; i < 4; ++i)
    for (int k = 0; k < 3; ++k) out[i][k] = x0[i][k] + t * (x1[i][k] - x0[i][k]);
}

}  // namespace

double point_triangle_distance(const double* p, const double* a, const double* b, const double* c, double w[3]) {
  // Voronoi regions of the triangle (Ericson, Real-Time Collision Detection, 5.1.5).
  double ab[3], ac[3], ap[3], bp[3], cp[3];
  sub(b, a, ab);
  sub(c, a, ac);
  sub(p, a, ap);
  auto finish = [&](double wa, double wb, double wc) {
    w[0] = wa;
    w[1] = wb;
    w[2] = wc;
    double q[3];
    for (int k = 0; k < 3; ++k) q[k] = p[k] - (wa * a[k] + wb * b[k] + wc * c[k]);
    return std::sqrt(dot(q, q));
  };
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return finish(1, 0, 0);
  sub(p, b, bp);
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return finish(0, 1, 0);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return finish(1 - v, v, 0);
  }
  sub(p, c, cp);
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return finish(0, 0, 1);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double v = d2 / (d2 - d6);
    return finish(1 - v, 0, v);
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double v = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return finish(0, 1 - v, v);
  }
  const double den = va + vb + vc;
  if (!(den > 0) || !std::isfinite(1.0 / den)) {
    // Degenerate (zero-area) triangle: the closest of the three edges.
    double best = 1e300;
    const double* v[3] = {a, b, c};
    for (int e = 0; e < 3; ++e) {
      const double s = point_segment_param(p, v[e], v[(e + 1) % 3]);
      double ww[3] = {0, 0, 0};
      ww[e] = 1 - s;
      ww[(e + 1) % 3] = s;
      double q[3];
      for (int k = 0; k < 3; ++k) q[k] = p[k] - (ww[0] * a[k] + ww[1] * b[k] + ww[2] * c[k]);
      const double dd = std::sqrt(dot(q, q));
      if (dd < best) {
        best = dd;
        w[0] = ww[0], w[1] = ww[1], w[2] = ww[2];
      }
    }
    return best;
  }
  const double v = vb / den, u = vc / den;
  return finish(1 - v - u, v, u);
}

double segment_segment_distance(const double* p0, const double* p1, const double* q0, const double* q1, double& s,
                                double& t) {
  // Ericson 5.1.9, with relative tolerances for degenerate and parallel segments.
  double d1[3], d2[3], r[3];
  sub(p1, p0, d1);
  sub(q1, q0, d2);
  sub(p0, q0, r);
  const double a = dot(d1, d1), e = dot(d2, d2), f = dot(d2, r);
  const double tiny = 1e-30;
  if (a <= tiny && e <= tiny) {
    s = t = 0;
  } else if (a <= tiny) {
    s = 0;
    t = clamp01(f / e);
  } else {
    const double c = dot(d1, r);
    if (e <= tiny) {
      t = 0;
      s = clamp01(-c / a);
    } else {
      const double b = dot(d1, d2);
      const double den = a * e - b * b;
      s = den > 1e-14 * a * e ? clamp01((b * f - c * e) / den) : 0.0;
      t = (b * s + f) / e;
      if (t < 0) {
        t = 0;
        s = clamp01(-c / a);
      } else if (t > 1) {
        t = 1;
        s = clamp01((b - c) / a);
      }
    }
  }
  double q[3];
  for (int k = 0; k < 3; ++k) q[k] = (p0[k] + s * d1[k]) - (q0[k] + t * d2[k]);
  return std::sqrt(dot(q, q));
}

int cubic_candidate_times(double c0, double c1, double c2, double c3, double out[7]) {
  auto f = [&](double t) { return ((c3 * t + c2) * t + c1) * t + c0; };
  // Critical points: roots of 3 c3 t^2 + 2 c2 t + c1 in (0, 1).
  double pts[4];
  int np = 0;
  pts[np++] = 0.0;
  const double A = 3 * c3, B = 2 * c2, C = c1;
  const double scale = std::abs(A) + std::abs(B) + std::abs(C);
  double crit[2];
  int nc = 0;
  if (scale > 0) {
    if (std::abs(A) <= 1e-14 * scale) {
      if (B != 0) crit[nc++] = -C / B;
    } else {
      const double disc = B * B - 4 * A * C;
      if (disc >= 0) {
        const double q = -0.5 * (B + std::copysign(std::sqrt(disc), B));
        crit[nc++] = q / A;
        if (q != 0) crit[nc++] = C / q;
      }
    }
  }
  if (nc == 2 && crit[0] > crit[1]) std::swap(crit[0], crit[1]);
  for (int i = 0; i < nc; ++i)
    if (crit[i] > 0 && crit[i] < 1) pts[np++] = crit[i];
  pts[np++] = 1.0;
  int n = 0;
  for (int i = 0; i + 1 < np; ++i) {
    double lo = pts[i], hi = pts[i + 1];
    double flo = f(lo), fhi = f(hi);
    if ((flo < 0 && fhi > 0) || (flo > 0 && fhi < 0)) {
      // f is monotone on [lo, hi]: bisection to full precision.
      for (int it = 0; it < 200 && hi - lo > 1e-16; ++it) {
        const double mid = 0.5 * (lo + hi);
        const double fm = f(mid);
        if (fm == 0) {
          lo = hi = mid;
          break;
        }
        if ((fm < 0) == (flo < 0)) {
          lo = mid;
          flo = fm;
        } else {
          hi = mid;
        }
      }
      out[n++] = 0.5 * (lo + hi);
    }
    if (i + 1 < np - 1) out[n++] = pts[i + 1];  // interior critical point (touching)
  }
  out[n++] = 1.0;
  std::sort(out, out + n);
  return n;
}

bool ccd_vertex_triangle(const double x0[4][3], const double x1[4][3], double tol, double& t) {
  double u0[3], w0[3], r0[3], du[3], dw[3], dr[3], e[4][3];
  for (int i = 0; i < 4; ++i) sub(x1[i], x0[i], e[i]);
  sub(x0[2], x0[1], u0);
  sub(x0[3], x0[1], w0);
  sub(x0[0], x0[1], r0);
  sub(e[2], e[1], du);
  sub(e[3], e[1], dw);
  sub(e[0], e[1], dr);
  double c[4];
  coplanarity_cubic(u0, du, w0, dw, r0, dr, c);
  return first_contact(
      c, tol,
      [&](double s) {
        double x[4][3], w[3];
        lerp4(x0, x1, s, x);
        return point_triangle_distance(x[0], x[1], x[2], x[3], w);
      },
      t);
}

bool ccd_edge_edge(const double x0[4][3], const double x1[4][3], double tol, double& t) {
  double u0[3], w0[3], r0[3], du[3], dw[3], dr[3], e[4][3];
  for (int i = 0; i < 4; ++i) sub(x1[i], x0[i], e[i]);
  sub(x0[1], x0[0], u0);
  sub(x0[3], x0[2], w0);
  sub(x0[2], x0[0], r0);
  sub(e[1], e[0], du);
  sub(e[3], e[2], dw);
  sub(e[2], e[0], dr);
  double c[4];
  coplanarity_cubic(u0, du, w0, dw, r0, dr, c);
  return first_contact(
      c, tol,
      [&](double s) {
        double x[4][3], a, b;
        lerp4(x0, x1, s, x);
        return segment_segment_distance(x[0], x[1], x[2], x[3], a, b);
      },
      t);
}

// Separating axis between the centres (see the header).
bool segments_farther_than(const double* p0, const double* p1, const double* q0, const double* q1, double r) {
  double m[3], de[3], df[3];
  for (int k = 0; k < 3; ++k) {
    m[k] = 0.5 * ((q0[k] + q1[k]) - (p0[k] + p1[k]));
    de[k] = p1[k] - p0[k];
    df[k] = q1[k] - q0[k];
  }
  // On an axis u (any nonzero vector): every point of the second segment is at least
  // (u.m - |u.de| / 2 - |u.df| / 2) / |u| beyond every point of the first along u, so the
  // distance is at least that; it is >= r when num = u.m - (|u.de| + |u.df|) / 2 > 0 and
  // num >= r |u|. Axes: m itself, then the parts of m across each segment (segments side by
  // side, offset along their length).
  auto gap_at_least_r = [&](const double* u) {
    const double num = dot(u, m) - 0.5 * (std::abs(dot(u, de)) + std::abs(dot(u, df)));
    return num > 0 && num >= r * std::sqrt(dot(u, u));
  };
  if (gap_at_least_r(m)) return true;
  auto across = [&](const double* d) {
    const double dd = dot(d, d);
    if (!(dd > 0)) return false;
    const double md = dot(m, d) / dd;
    const double u[3] = {m[0] - md * d[0], m[1] - md * d[1], m[2] - md * d[2]};
    return gap_at_least_r(u);
  };
  return across(de) || across(df);
}

bool point_triangle_farther_than(const double* p, const double* a, const double* b, const double* c, double r) {
  // On u = p - centroid: the triangle lies within its vertices' largest projection from the
  // centroid, so the distance is at least (|u|^2 - that) / |u| when that is positive.
  double ctr[3], u[3];
  for (int k = 0; k < 3; ++k) {
    ctr[k] = (a[k] + b[k] + c[k]) * (1.0 / 3.0);
    u[k] = p[k] - ctr[k];
  }
  double pa[3], pb[3], pc[3];
  sub(a, ctr, pa);
  sub(b, ctr, pb);
  sub(c, ctr, pc);
  const double num = dot(u, u) - std::max({dot(u, pa), dot(u, pb), dot(u, pc)});
  return num > 0 && num >= r * std::sqrt(dot(u, u));
}

bool triangles_farther_than(const double* a0, const double* a1, const double* a2, const double* b0, const double* b1,
                            const double* b2, double r) {
  // On u = (centroid of b) - (centroid of a): every point of a projects at most pa, every point
  // of b at least pb (a point of a triangle is a convex combination of its vertices), so two
  // points are at least (pb - pa) / |u| apart.
  double u[3];
  for (int k = 0; k < 3; ++k) u[k] = ((b0[k] + b1[k] + b2[k]) - (a0[k] + a1[k] + a2[k])) * (1.0 / 3.0);
  const double pa = std::max({dot(u, a0), dot(u, a1), dot(u, a2)});
  const double pb = std::min({dot(u, b0), dot(u, b1), dot(u, b2)});
  const double num = pb - pa;
  return num > 0 && num >= r * std::sqrt(dot(u, u));
}

void TriangleBvh::build(const std::vector<double>& centroids) {
  const Index nt = static_cast<Index>(centroids.size() / 3);
  nodes_.clear();
  if (nt == 0) return;
  nodes_.reserve(2 * static_cast<std::size_t>(nt));
  std::vector<Index> ids(nt);
  std::iota(ids.begin(), ids.end(), 0);
  // Pre-order: a parent's index is below its children's (refit runs backwards).
  struct Builder {
    std::vector<Node>& nodes;
    const std::vector<double>& c;
    Index make(Index* first, Index* last) {
      const Index me = static_cast<Index>(nodes.size());
      nodes.emplace_back();
      if (last - first == 1) {
        nodes[me].tri = *first;
        return me;
      }
      double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
      for (Index* p = first; p != last; ++p)
        for (int k = 0; k < 3; ++k) {
          lo[k] = std::min(lo[k], c[3 * *p + k]);
          hi[k] = std::max(hi[k], c[3 * *p + k]);
        }
      int axis = 0;
      for (int k = 1; k < 3; ++k)
        if (hi[k] - lo[k] > hi[axis] - lo[axis]) axis = k;
      Index* mid = first + (last - first) / 2;
      std::nth_element(first, mid, last, [&](Index a, Index b) { return c[3 * a + axis] < c[3 * b + axis]; });
      const Index l = make(first, mid);
      const Index r = make(mid, last);
      nodes[me].left = l;
      nodes[me].right = r;
      return me;
    }
  } b{nodes_, centroids};
  b.make(ids.data(), ids.data() + nt);
  // Leaves in depth-first order, and each node's range of them (pre-order: children after
  // their parent, so a backward pass sums the counts).
  leaf_nodes_.clear();
  for (std::size_t i = 0; i < nodes_.size(); ++i)
    if (nodes_[i].tri >= 0) leaf_nodes_.push_back(static_cast<Index>(i));
  for (std::size_t i = nodes_.size(); i-- > 0;) {
    Node& n = nodes_[i];
    if (n.tri >= 0) {
      n.count = 1;
    } else {
      n.count = nodes_[n.left].count + nodes_[n.right].count;
    }
  }
  for (std::size_t k = 0; k < leaf_nodes_.size(); ++k) nodes_[leaf_nodes_[k]].first = static_cast<Index>(k);
  leaves_.assign(leaf_nodes_.size(), Leaf{});
  for (std::size_t k = 0; k < leaf_nodes_.size(); ++k) leaves_[k].tri = nodes_[leaf_nodes_[k]].tri;
  have_vertices_ = false;
  for (std::size_t i = nodes_.size(); i-- > 0;)
    if (nodes_[i].tri < 0) nodes_[i].first = nodes_[nodes_[i].left].first;
  parent_.assign(nodes_.size(), -1);
  leaf_.assign(nt, -1);
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const Node& n = nodes_[i];
    if (n.tri >= 0) {
      leaf_[n.tri] = static_cast<Index>(i);
    } else {
      parent_[n.left] = static_cast<Index>(i);
      parent_[n.right] = static_cast<Index>(i);
    }
  }
}

void TriangleBvh::set_vertices(const std::vector<Index>& tris) {
  for (Leaf& l : leaves_)
    for (int k = 0; k < 3; ++k) l.v[k] = tris[3 * static_cast<std::size_t>(l.tri) + k];
  have_vertices_ = true;
}

void TriangleBvh::update_leaf(Index tri, const double* lo, const double* hi) {
  Index i = leaf_[tri];
  for (int k = 0; k < 3; ++k) {
    leaves_[nodes_[i].first].lo[k] = nodes_[i].lo[k] = lo[k];
    leaves_[nodes_[i].first].hi[k] = nodes_[i].hi[k] = hi[k];
  }
  for (i = parent_[i]; i >= 0; i = parent_[i]) {
    Node& n = nodes_[i];
    const Node& l = nodes_[n.left];
    const Node& r = nodes_[n.right];
    for (int k = 0; k < 3; ++k) {
      n.lo[k] = std::min(l.lo[k], r.lo[k]);
      n.hi[k] = std::max(l.hi[k], r.hi[k]);
    }
  }
}

void TriangleBvh::refit(const double* tri_lo, const double* tri_hi, double pad) {
  for (std::size_t i = nodes_.size(); i-- > 0;) {
    Node& n = nodes_[i];
    if (n.tri >= 0) {
      Leaf& l = leaves_[n.first];
      for (int k = 0; k < 3; ++k) {
        l.lo[k] = n.lo[k] = tri_lo[3 * n.tri + k] - pad;
        l.hi[k] = n.hi[k] = tri_hi[3 * n.tri + k] + pad;
      }
    } else {
      const Node& l = nodes_[n.left];
      const Node& r = nodes_[n.right];
      for (int k = 0; k < 3; ++k) {
        n.lo[k] = std::min(l.lo[k], r.lo[k]);
        n.hi[k] = std::max(l.hi[k], r.hi[k]);
      }
    }
  }
}

void TriangleBvh::split(std::size_t target, std::vector<std::array<Index, 2>>& tasks) const {
  tasks.clear();
  if (nodes_.empty()) return;
  // The first levels of pairs_from's recursion, breadth-first: every round replaces each task
  // by its children (the same rule as pairs_from), dropping the ones that emit nothing.
  auto overlap = [](const Node& a, const Node& b) {
    return a.lo[0] <= b.hi[0] && b.lo[0] <= a.hi[0] && a.lo[1] <= b.hi[1] && b.lo[1] <= a.hi[1] &&
           a.lo[2] <= b.hi[2] && b.lo[2] <= a.hi[2];
  };
  auto extent = [](const Node& a) { return (a.hi[0] - a.lo[0]) + (a.hi[1] - a.lo[1]) + (a.hi[2] - a.lo[2]); };
  constexpr std::array<Index, 2> kDropped = {-1, -1};
  tasks.push_back({0, 0});
  bool changed = true;
  while (changed && tasks.size() < target) {
    changed = false;
    const std::size_t n0 = tasks.size();
    for (std::size_t i = 0; i < n0; ++i) {
      const auto [a, b] = tasks[i];
      if (a < 0) continue;
      const Node& A = nodes_[a];
      if (a == b) {
        if (A.tri >= 0) {
          tasks[i] = kDropped;
          continue;
        }
        tasks[i] = {A.left, A.left};
        tasks.push_back({A.right, A.right});
        tasks.push_back({A.left, A.right});
        changed = true;
        continue;
      }
      const Node& B = nodes_[b];
      if (!overlap(A, B)) {
        tasks[i] = kDropped;
        continue;
      }
      if (A.tri >= 0 && B.tri >= 0) continue;  // a leaf pair: pairs_from emits it
      if (B.tri >= 0 || (A.tri < 0 && extent(A) >= extent(B))) {
        tasks[i] = {A.left, b};
        tasks.push_back({A.right, b});
      } else {
        tasks[i] = {a, B.left};
        tasks.push_back({a, B.right});
      }
      changed = true;
    }
  }
  tasks.erase(std::remove(tasks.begin(), tasks.end(), kDropped), tasks.end());
}

}  // namespace selfcol

// ---------------------------------------------------------------------------------------------

namespace {

std::string fmt(double v) {
  std::ostringstream os;
  os.precision(4);
  os << v;
  return os.str();
}

// Tuning of the response (see docs/NUMERICS.md, "Self-collision").
constexpr double kRepulsionFraction = 0.25;  ///< of the missing thickness restored per step
constexpr double kCcdTolerance = 1e-3;       ///< CCD contact distance, times the thickness
constexpr double kCcdSeparation = 0.1;       ///< CCD impulses leave this gap, times the thickness
// Reach of a vertex at a rebuild of the candidate lists (how far it may move before the next):
// max(kReachMin th, 2 |d|) + min(kReachSteps |d|, cap), |d| its displacement this step, cap
// kReachCap th for small steps (explicit integrators: a vertex moving th/16 or more per step
// keeps its lists for about 24 steps instead of 16; on the draped cloth at 128^2 this cut the
// full rebuilds from 7.0 % to 4.8 % of the steps for 26 % more pairs in the lists, see
// docs/CONTACT.md "What it costs"), kLargeStepReachCap th for large steps (implicit ones, which
// rebuild about every step with boxes a displacement wide).
constexpr double kReachMin = 0.5;
constexpr double kReachSteps = 16.0;
constexpr double kReachCap = 1.0;
// cap / th for large steps. A vertex's neighbours in the sheet that share no vertex with it lie
// at least about 0.71 edge = 2.83 th away (th a quarter of the edge, as recommended), and a pair
// is listed below th + r_a + r_b: a reach of at most 0.9 th keeps them out of the lists. With
// th/2 (until 2026-12-02) a slow vertex had reach th and the lists held all of them (25 000
// pairs at 64^2 where th/4 lists 2 500); th/4 gives 0.75 th, and lists that last as long (the
// lists are renewed about every step at 128^2 either way). docs/CONTACT.md "What it costs".
constexpr double kLargeStepReachCap = 0.25;
// Under proximity_pairs (large steps), a refresh instead of a rebuild up to this fraction of the vertices.
constexpr double kLargeStepRefreshFraction = 1.0 / 16;
// Traversal tasks of a parallel rebuild (fixed, so the pairs' order does not depend on the threads).
constexpr std::size_t kTraversalTasks = 64;

constexpr const char* kCannotUndo =
    "self-collision keeps layers on the side they start on, so it cannot undo a crossing.";

/// "N pairs of non-adjacent triangles, e.g. triangles a and b" by the exact check of `loom
/// check`, or empty when the cloth at x does not intersect itself.
std::string crossing_pairs(const Mesh& mesh, const std::vector<double>& x) {
  std::vector<std::array<Index, 2>> pairs;
  const std::size_t n = count_intersecting_pairs(mesh, x, &pairs);
  if (n == 0) return {};
  return std::to_string(n) + " pairs of non-adjacent triangles, e.g. triangles " + std::to_string(pairs[0][0]) +
         " and " + std::to_string(pairs[0][1]);
}

}  // namespace

void SelfCollision::refuse_crossing_state(const Mesh& mesh, const std::vector<double>& x, const std::string& where,
                                          bool program) {
  const std::string crossing = crossing_pairs(mesh, x);
  if (crossing.empty()) return;
  if (program)
    throw InputError("the state set through Scene::state intersects itself (" + crossing +
                     "), and the scene has self_collision: " + kCannotUndo +
                     " Fix: start from a state without crossings (loom::count_intersecting_pairs finds them; a state "
                     "saved from a run with self-collision has none), or call Simulation::accept_state() to run "
                     "self-collision on it anyway (the crossing then stays), or remove self_collision.");
  throw InputError(where + ": the cloth in this state intersects itself (" + crossing + "), and the scene has "
                   "self_collision: " + kCannotUndo + " Fix: rerun the scene from its start with --overwrite "
                   "(self-collision keeps a cloth that starts without crossings free of them), or remove "
                   "self_collision from the run's scene.yaml to continue without it.");
}

std::unique_ptr<SelfCollision> SelfCollision::parse(const Params& p, const Mesh& mesh, const std::vector<double>& x) {
  if (!p.valid()) return nullptr;
  if (!p.is_map()) p.fail("must be a mapping like {thickness: 0.002, friction: 0.3} (thickness in m).");
  Options o;
  Params th = p.child("thickness");
  if (!th.valid()) p.fail("missing 'thickness' (m, > 0): the gap kept between layers of cloth, e.g. thickness: 0.002.");
  o.thickness = th.as_double();
  if (!std::isfinite(o.thickness) || o.thickness <= 0)
    th.fail("thickness must be a finite number > 0 (got " + fmt(o.thickness) +
            "). Fix: give the gap kept between cloth layers in m, e.g. 0.002 (a quarter of the edge length or less).");
  Params fr = p.child("friction");
  if (fr.valid()) {
    o.friction = fr.as_double();
    if (!std::isfinite(o.friction) || o.friction < 0)
      fr.fail("friction must be a finite number >= 0 (got " + fmt(o.friction) +
              "). Fix: give a Coulomb coefficient, e.g. 0.3 (0 = frictionless).");
  }
  p.check_unused();
  // A cloth that starts intersecting itself cannot be untangled by the response (it keeps each
  // pair on the side it starts on), which would then fight the crossing at every step.
  const std::string crossing = crossing_pairs(mesh, x);
  if (!crossing.empty())
    p.fail("the cloth as built intersects itself (" + crossing + "); " + kCannotUndo +
           " Fix: give a mesh without self-intersections (separate the layers by more than the thickness), or remove "
           "self_collision.");
  auto sc = std::make_unique<SelfCollision>(o, mesh);
  const double dmin = sc->min_distance(x, o.thickness);
  if (dmin < o.thickness)
    th.fail("thickness " + fmt(o.thickness) + " m exceeds the smallest distance between non-adjacent elements of the cloth as built (" +
            fmt(dmin) + " m): neighbours in the sheet, or layers of the mesh that start that close, would repel each other. Fix: use a thickness below " +
            fmt(dmin) + " m (about half of it is a good choice), refine the mesh, or separate its layers.");
  return sc;
}

SelfCollision::SelfCollision(const Options& o, const Mesh& mesh) : opt_(o) {
  nv_ = mesh.num_vertices();
  nt_ = mesh.num_triangles();
  tris_ = mesh.triangles;
  edges_ = mesh.edges();
  margin_ = o.thickness;
  // Ownership: each vertex and edge is tested by the first triangle that contains it, so that a
  // pair of overlapping triangles yields every element pair exactly once.
  own_verts_.assign(nt_, {-1, -1, -1});
  own_edges_.assign(nt_, {-1, -1, -1});
  tri_edges_.assign(3 * static_cast<std::size_t>(nt_), -1);
  std::vector<std::uint8_t> vseen(nv_, 0), eseen(edges_.size(), 0);
  std::vector<double> centroids(3 * static_cast<std::size_t>(nt_));
  for (Index t = 0; t < nt_; ++t) {
    const Index* v = &tris_[3 * t];
    int nvo = 0, neo = 0;
    for (int k = 0; k < 3; ++k) {
      if (!vseen[v[k]]) {
        vseen[v[k]] = 1;
        own_verts_[t][nvo++] = v[k];
      }
      const std::array<Index, 2> e = {std::min(v[k], v[(k + 1) % 3]), std::max(v[k], v[(k + 1) % 3])};
      const auto it = std::lower_bound(edges_.begin(), edges_.end(), e);
      const auto ei = static_cast<std::size_t>(it - edges_.begin());
      tri_edges_[3 * t + k] = static_cast<Index>(ei);
      if (!eseen[ei]) {
        eseen[ei] = 1;
        own_edges_[t][neo++] = static_cast<Index>(ei);
      }
      for (int q = 0; q < 3; ++q) centroids[3 * t + q] += mesh.positions[3 * v[k] + q] / 3.0;
    }
  }
  bvh_.build(centroids);
  bvh_.set_vertices(tris_);
  const std::size_t n3 = 3 * static_cast<std::size_t>(nv_);
  x0_.assign(n3, 0.0);
  d_.assign(n3, 0.0);
  inv_mass_.assign(nv_, 0.0);
  touched_.reserve(nv_);
  touched_flag_.assign(nv_, 0);
  tlo_.assign(3 * static_cast<std::size_t>(nt_), 0.0);
  thi_.assign(3 * static_cast<std::size_t>(nt_), 0.0);
  ref_x_.assign(n3, 0.0);
  moved_.assign(nv_, 0.0);
  step_len_.assign(nv_, 0.0);
  len0_.assign(nv_, 0.0);
  frozen_.assign(nv_, 0);
  // Vertex -> incident triangles and edges (CSR).
  vt_off_.assign(nv_ + 1, 0);
  ve_off_.assign(nv_ + 1, 0);
  for (Index t = 0; t < nt_; ++t)
    for (int k = 0; k < 3; ++k) ++vt_off_[tris_[3 * t + k] + 1];
  for (const auto& e : edges_) ++ve_off_[e[0] + 1], ++ve_off_[e[1] + 1];
  for (Index i = 0; i < nv_; ++i) vt_off_[i + 1] += vt_off_[i], ve_off_[i + 1] += ve_off_[i];
  vt_adj_.assign(vt_off_[nv_], 0);
  ve_adj_.assign(ve_off_[nv_], 0);
  {
    std::vector<Index> fill_t(vt_off_.begin(), vt_off_.end() - 1), fill_e(ve_off_.begin(), ve_off_.end() - 1);
    for (Index t = 0; t < nt_; ++t)
      for (int k = 0; k < 3; ++k) vt_adj_[fill_t[tris_[3 * t + k]]++] = t;
    for (Index e = 0; e < static_cast<Index>(edges_.size()); ++e)
      for (int k = 0; k < 2; ++k) ve_adj_[fill_e[edges_[e][k]]++] = e;
  }
  vflag_.assign(nv_, 0);
  tflag_.assign(nt_, 0);
  eflag_.assign(edges_.size(), 0);
  refresh_v_.reserve(nv_);
  refresh_t_.reserve(nt_);
  refresh_e_.reserve(edges_.size());
  reach_.assign(nv_, 0.0);
  trec_.assign(nt_, TriRecord{});
  tri_slot_.assign(nt_, 0);
  slot_tri_.assign(nt_, 0);
  for (Index k = 0; k < nt_; ++k) {
    slot_tri_[k] = bvh_.leaf_triangle(k);
    tri_slot_[slot_tri_[k]] = k;
  }
  for (Index t = 0; t < nt_; ++t) {
    TriRecord& R = trec_[tri_slot_[t]];
    R.own = 0;
    for (int k = 0; k < 3; ++k) {
      R.v[k] = tris_[3 * t + k];
      R.e[k] = tri_edges_[3 * t + k];
      for (int j = 0; j < 3; ++j) {
        if (own_verts_[t][j] >= 0 && own_verts_[t][j] == R.v[k]) R.own |= 1u << k;
        if (own_edges_[t][j] >= 0 && own_edges_[t][j] == R.e[k]) R.own |= 8u << k;
      }
    }
  }
  // Element pairs of triangles that share a vertex (see nb_vt_), by owner triangle.
  {
    std::vector<Index> nbrs;
    for (Index P = 0; P < nt_; ++P) {
      const TriRecord& RP = trec_[tri_slot_[P]];
      nbrs.clear();
      for (int k = 0; k < 3; ++k)
        for (Index j = vt_off_[RP.v[k]]; j < vt_off_[RP.v[k] + 1]; ++j)
          if (vt_adj_[j] != P) nbrs.push_back(vt_adj_[j]);
      std::sort(nbrs.begin(), nbrs.end());
      nbrs.erase(std::unique(nbrs.begin(), nbrs.end()), nbrs.end());
      for (const Index T : nbrs) {
        const TriRecord& RT = trec_[tri_slot_[T]];
        for (int k = 0; k < 3; ++k) {
          const Index v = RP.v[k];
          if ((RP.own >> k & 1u) && v != RT.v[0] && v != RT.v[1] && v != RT.v[2]) nb_vt_.push_back({v, T});
        }
        for (int ka = 0; ka < 3; ++ka) {
          if (!(RP.own >> (3 + ka) & 1u)) continue;
          const Index e = RP.e[ka];
          for (int kb = 0; kb < 3; ++kb) {
            if (!(RT.own >> (3 + kb) & 1u)) continue;
            const Index f = RT.e[kb];
            if (!(e < f)) continue;  // the pair once, from the lower edge's owner
            const auto& E = edges_[e];
            const auto& F = edges_[f];
            if (E[0] == F[0] || E[0] == F[1] || E[1] == F[0] || E[1] == F[1]) continue;
            nb_ee_.push_back({e, f});
          }
        }
      }
    }
  }
  // The neighbour-list pairs by element (CSR), for refresh(): the pairs of a refreshed vertex,
  // triangle or edge among them are found without a traversal.
  {
    auto csr = [](std::size_t n, const auto& pairs, auto&& keys, std::vector<Index>& off, std::vector<Index>& idx) {
      off.assign(n + 1, 0);
      for (const auto& p : pairs)
        for (const Index k : keys(p)) ++off[static_cast<std::size_t>(k) + 1];
      for (std::size_t i = 0; i < n; ++i) off[i + 1] += off[i];
      idx.assign(static_cast<std::size_t>(off[n]), 0);
      std::vector<Index> fill(off.begin(), off.end() - 1);
      for (std::size_t q = 0; q < pairs.size(); ++q)
        for (const Index k : keys(pairs[q])) idx[static_cast<std::size_t>(fill[static_cast<std::size_t>(k)]++)] = static_cast<Index>(q);
    };
    csr(static_cast<std::size_t>(nv_), nb_vt_, [](const std::array<Index, 2>& p) { return std::array<Index, 1>{p[0]}; },
        nbv_off_, nbv_idx_);
    csr(static_cast<std::size_t>(nt_), nb_vt_, [](const std::array<Index, 2>& p) { return std::array<Index, 1>{p[1]}; },
        nbt_off_, nbt_idx_);
    csr(edges_.size(), nb_ee_, [](const std::array<Index, 2>& p) { return p; }, nbe_off_, nbe_idx_);
    refresh_nbvt_.reserve(nb_vt_.size() / 8);
    refresh_nbee_.reserve(nb_ee_.size() / 8);
  }
  vt_.reserve(static_cast<std::size_t>(nv_));
  ee_.reserve(static_cast<std::size_t>(nv_));
  stack_.reserve(256);
  tasks_.reserve(256);
}

void SelfCollision::begin_step(const State& s) { std::memcpy(x0_.data(), s.x.data(), x0_.size() * sizeof(double)); }

// Distance of a pair at positions x; w are the weights of the relative position
// sum_i w_i x_i (vertex minus triangle point, or second edge point minus first), n its direction.
double SelfCollision::pair_distance(bool vt, const Index idx[4], const double* x, double w[4], double n[3]) const {
  const double* p[4] = {&x[3 * idx[0]], &x[3 * idx[1]], &x[3 * idx[2]], &x[3 * idx[3]]};
  double dist;
  if (vt) {
    double b[3];
    dist = selfcol::point_triangle_distance(p[0], p[1], p[2], p[3], b);
    w[0] = 1;
    w[1] = -b[0];
    w[2] = -b[1];
    w[3] = -b[2];
  } else {
    double s, t;
    dist = selfcol::segment_segment_distance(p[0], p[1], p[2], p[3], s, t);
    w[0] = -(1 - s);
    w[1] = -s;
    w[2] = 1 - t;
    w[3] = t;
  }
  for (int k = 0; k < 3; ++k) n[k] = w[0] * p[0][k] + w[1] * p[1][k] + w[2] * p[2][k] + w[3] * p[3][k];
  const double len = std::sqrt(selfcol::dot(n, n));
  if (len > 1e-12 * opt_.thickness) {
    for (int k = 0; k < 3; ++k) n[k] /= len;
  } else {
    // Touching: the normal of the triangle, or of the two edges.
    double a[3], b[3];
    if (vt) {
      selfcol::sub(p[2], p[1], a);
      selfcol::sub(p[3], p[1], b);
    } else {
      selfcol::sub(p[1], p[0], a);
      selfcol::sub(p[3], p[2], b);
    }
    selfcol::cross(a, b, n);
    const double l = std::sqrt(selfcol::dot(n, n));
    if (l > 0)
      for (int k = 0; k < 3; ++k) n[k] /= l;
    else
      n[0] = 1, n[1] = n[2] = 0;
  }
  return dist;
}

bool SelfCollision::pair_ccd(bool vt, const Index idx[4], double tol, double& t) const {
  double a[4][3], b[4][3];
  for (int i = 0; i < 4; ++i)
    for (int k = 0; k < 3; ++k) {
      a[i][k] = x0_[3 * idx[i] + k];
      b[i][k] = a[i][k] + d_[3 * idx[i] + k];
    }
  return vt ? selfcol::ccd_vertex_triangle(a, b, tol, t) : selfcol::ccd_edge_edge(a, b, tol, t);
}

bool SelfCollision::respond(const Index idx[4], const double w[4], const double n[3], double dpos, double h, State& s) {
  double W = 0;
  for (int i = 0; i < 4; ++i) W += w[i] * w[i] * inv_mass_[idx[i]];
  if (!(W > 0)) return false;
  bool changed = false;
  if (dpos > 0) {
    const double I = dpos / W;
    for (int i = 0; i < 4; ++i) {
      const double c = w[i] * inv_mass_[idx[i]] * I;
      for (int k = 0; k < 3; ++k) d_[3 * idx[i] + k] += c * n[k];
    }
    changed = true;
  }
  double vrel[3] = {0, 0, 0};
  for (int i = 0; i < 4; ++i)
    for (int k = 0; k < 3; ++k) vrel[k] += w[i] * s.v[3 * idx[i] + k];
  const double vn = selfcol::dot(vrel, n);
  if (vn < 0) {
    // Inelastic: the relative normal velocity becomes zero.
    const double J = -vn / W;
    for (int i = 0; i < 4; ++i) {
      const double c = w[i] * inv_mass_[idx[i]] * J;
      for (int k = 0; k < 3; ++k) s.v[3 * idx[i] + k] += c * n[k];
    }
    // Coulomb friction: the relative tangential velocity loses up to mu times the normal change.
    double vt[3];
    for (int k = 0; k < 3; ++k) vt[k] = vrel[k] - vn * n[k];
    const double vtl = std::sqrt(selfcol::dot(vt, vt));
    if (opt_.friction > 0 && vtl > 0) {
      const double dvt = std::min(vtl, opt_.friction * -vn);
      const double Jt = dvt / (W * vtl);
      for (int i = 0; i < 4; ++i) {
        const double c = -w[i] * inv_mass_[idx[i]] * Jt;
        for (int k = 0; k < 3; ++k) {
          s.v[3 * idx[i] + k] += c * vt[k];
          d_[3 * idx[i] + k] += h * c * vt[k];  // move as the corrected velocity would have
        }
      }
    }
    changed = true;
  }
  if (changed)
    for (int i = 0; i < 4; ++i) {
      if (!touched_flag_[idx[i]]) {
        touched_flag_[idx[i]] = 1;
        touched_.push_back(idx[i]);  // within the capacity reserved for every vertex
      }
      step_len_[idx[i]] = frame_step(&x0_[3 * idx[i]], &d_[3 * idx[i]]);
      max_growth_ = std::max(max_growth_, step_len_[idx[i]] - len0_[idx[i]]);
    }
  responded_ |= changed;
  return changed;
}

void SelfCollision::triangle_box(Index t, double gap) {
  TriRecord& R = trec_[tri_slot_[t]];
  const double* X = ref_x_.data();
  for (int k = 0; k < 3; ++k) {
    R.r[k] = reach_[R.v[k]];
    for (int q = 0; q < 3; ++q) R.x[3 * k + q] = X[3 * R.v[k] + q];
  }
  for (int k = 0; k < 3; ++k) R.er[k] = std::max(R.r[k], R.r[(k + 1) % 3]);
  R.tr = std::max({R.r[0], R.r[1], R.r[2]});
  for (int q = 0; q < 3; ++q) {
    R.lo[q] = tlo_[3 * t + q] = std::min({R.x[q], R.x[3 + q], R.x[6 + q]}) - (R.tr + 0.5 * gap);
    R.hi[q] = thi_[3 * t + q] = std::max({R.x[q], R.x[3 + q], R.x[6 + q]}) + (R.tr + 0.5 * gap);
  }
}

void SelfCollision::traverse(double gap, bool exact, bool refreshed) {
  // Traversal: a fixed number of independent node pairs (tasks) shared out among the threads,
  // each task filling its own lists (kept between calls: no allocation once they have grown),
  // then joined in task order. The tasks do not depend on the thread count, so neither does
  // the order in which the response visits the pairs, and no sort is needed.
  const bool par = nv_ >= kParallelMinVertices;
  const int nth = par ? std::max(1, omp_get_max_threads()) : 1;
  // A rebuild traverses the hierarchy's node pairs from kTraversalTasks fixed tasks; a refresh
  // (`refreshed`) queries it once per group of refreshed triangles (refresh_group_).
  if (!refreshed) bvh_.split(par ? kTraversalTasks : 1, tasks_);
  const std::size_t ngroups = refresh_group_.empty() ? 0 : refresh_group_.size() - 1;
  // The leaf pairs of triangles sharing a vertex are left to the neighbour lists (nb_vt_,
  // nb_ee_): tasks ntrav.. test their chunks; a refresh tests only the pairs of
  // them that refresh() selected (refresh_nbvt_, refresh_nbee_: a refreshed element in each).
  const std::size_t ntrav = refreshed ? ngroups : tasks_.size();
  const std::size_t ntasks = ntrav + kNeighbourChunks;
  if (task_vt_.size() < ntasks) {
    task_vt_.resize(ntasks);
    task_ee_.resize(ntasks);
  }
  if (static_cast<int>(tstack_.size()) < nth) tstack_.resize(nth);
  if (static_cast<int>(qstacks_.size()) < nth) qstacks_.resize(nth);
  auto share_vertex = [](const TriRecord& A, const TriRecord& B) { return selfcol::triangles_share_vertex(A.v, B.v); };
  auto overlap = [](const double* alo, const double* ahi, const double* blo, const double* bhi) {
    return alo[0] <= bhi[0] && blo[0] <= ahi[0] && alo[1] <= bhi[1] && blo[1] <= ahi[1] && alo[2] <= bhi[2] &&
           blo[2] <= ahi[2];
  };
  Index exact_count = 0;
  const double half_gap = 0.5 * gap;
#pragma omp parallel num_threads(nth) if (nth > 1)
  {
    const int me = omp_get_thread_num();
#pragma omp for schedule(dynamic, 1) reduction(+ : exact_count)
    for (std::size_t q = 0; q < ntasks; ++q) {
      std::vector<Pair>& vt = task_vt_[q];
      std::vector<Pair>& ee = task_ee_[q];
      vt.clear();
      ee.clear();
      // The element tests, for the traversal's leaf pairs and the neighbour lists alike: vertex
      // v at p (reach rv) against triangle t (record T): its padded box against T's, then with
      // `exact` the distance below gap + the reaches; listed when it passes.
      auto test_vt = [&](Index v, const double* p, double rv, Index t, const TriRecord& T) {
        const double pad = rv + half_gap;
        const double plo[3] = {p[0] - pad, p[1] - pad, p[2] - pad}, phi[3] = {p[0] + pad, p[1] + pad, p[2] + pad};
        if (!overlap(plo, phi, T.lo, T.hi)) return;
        double dist = 0;
        if (exact) {
          const double r = gap + rv + T.tr;
          if (selfcol::point_triangle_farther_than(p, &T.x[0], &T.x[3], &T.x[6], r)) return;
          ++exact_count;
          double w[3];
          dist = selfcol::point_triangle_distance(p, &T.x[0], &T.x[3], &T.x[6], w);
          if (!(dist < r)) return;
        }
        vt.push_back({v, t, dist});
      };
      // The box of segment p0 p1 grown by pad.
      auto edge_box = [](const double* p0, const double* p1, double pad, double* lo, double* hi) {
        for (int c = 0; c < 3; ++c) {
          lo[c] = std::min(p0[c], p1[c]) - pad;
          hi[c] = std::max(p0[c], p1[c]) + pad;
        }
      };
      // Edge e (p0 p1, reach er, padded box elo / ehi) against edge f (q0 q1, reach fr).
      auto test_ee = [&](Index e, const double* p0, const double* p1, double er, const double* elo,
                         const double* ehi, Index f, const double* q0, const double* q1, double fr) {
        double flo[3], fhi[3];
        edge_box(q0, q1, fr + half_gap, flo, fhi);
        if (!overlap(elo, ehi, flo, fhi)) return;
        double dist = 0;
        if (exact) {
          const double r = gap + er + fr;
          if (selfcol::segments_farther_than(p0, p1, q0, q1, r)) return;
          ++exact_count;
          double ss, tt;
          dist = selfcol::segment_segment_distance(p0, p1, q0, q1, ss, tt);
          if (!(dist < r)) return;
        }
        ee.push_back({std::min(e, f), std::max(e, f), dist});
      };
      // Vertex k of record P against triangle t (record T).
      auto vert_tri = [&](const TriRecord& P, int k, Index t, const TriRecord& T) {
        const Index v = P.v[k];
        if (v == T.v[0] || v == T.v[1] || v == T.v[2]) return;
        test_vt(v, &P.x[3 * k], P.r[k], t, T);
      };
      // In a refresh, a leaf pair has at least one refreshed triangle, and
      // only the element pairs that the refresh dropped are looked at: those with a refreshed
      // vertex, triangle or edge (flags set by refresh()).
      auto emit = [&](Index A, Index B) {
        const TriRecord& RA = trec_[tri_slot_[A]];
        const TriRecord& RB = trec_[tri_slot_[B]];
        // (Triangles that share a vertex touch: the bound would not reject them.)
        const bool adjacent = share_vertex(RA, RB);
        if (exact && !adjacent && selfcol::triangles_farther_than(&RA.x[0], &RA.x[3], &RA.x[6], &RB.x[0], &RB.x[3], &RB.x[6],
                                                     gap + RA.tr + RB.tr))
          return;  // every element pair is listed below gap + its reaches <= gap + RA.tr + RB.tr
        const bool all_a = !refreshed || tflag_[A], all_b = !refreshed || tflag_[B];
        for (int k = 0; k < 3; ++k)
          if ((RA.own >> k & 1u) && (all_b || vflag_[RA.v[k]])) vert_tri(RA, k, B, RB);
        for (int k = 0; k < 3; ++k)
          if ((RB.own >> k & 1u) && (all_a || vflag_[RB.v[k]])) vert_tri(RB, k, A, RA);
        for (int ka = 0; ka < 3; ++ka) {
          if (!(RA.own >> (3 + ka) & 1u)) continue;
          const Index e = RA.e[ka];
          // Endpoints in edges_' order (lower vertex index first), as the lists always had them.
          int a0 = ka, a1 = (ka + 1) % 3;
          if (RA.v[a1] < RA.v[a0]) std::swap(a0, a1);
          const double *p0 = &RA.x[3 * a0], *p1 = &RA.x[3 * a1];
          double elo[3], ehi[3];
          edge_box(p0, p1, RA.er[ka] + half_gap, elo, ehi);
          // B's box holds its edges' boxes: an edge of A clear of it meets none of them.
          if (!overlap(elo, ehi, RB.lo, RB.hi)) continue;
          const bool all_f = !refreshed || eflag_[e];
          for (int kb = 0; kb < 3; ++kb) {
            if (!(RB.own >> (3 + kb) & 1u)) continue;
            const Index f = RB.e[kb];
            if (!(all_f || eflag_[f])) continue;
            int b0 = kb, b1 = (kb + 1) % 3;
            if (RB.v[b1] < RB.v[b0]) std::swap(b0, b1);
            if (RA.v[a0] == RB.v[b0] || RA.v[a0] == RB.v[b1] || RA.v[a1] == RB.v[b0] || RA.v[a1] == RB.v[b1]) continue;
            test_ee(e, p0, p1, RA.er[ka], elo, ehi, f, &RB.x[3 * b0], &RB.x[3 * b1], RB.er[kb]);
          }
        }
      };
      if (q < ntrav && !refreshed) {
        bvh_.pairs_from(tasks_[q], emit, tstack_[me], true);  // sharing pairs: in the lists below
        continue;
      }
      if (q < ntrav) {
        // A group of refreshed triangles: one query with the union of their boxes; every leaf T
        // it meets is paired with each group triangle t whose box overlaps T's (sharing no
        // vertex: those pairs are the neighbour lists'). A pair of two refreshed triangles is
        // taken from the lower index's side only (the other's group query meets it too).
        const Index g0 = refresh_group_[q], g1 = refresh_group_[q + 1];
        double ulo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, uhi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
        for (Index k = g0; k < g1; ++k) {
          const TriRecord& R = trec_[tri_slot_[refresh_t_[k]]];
          for (int c = 0; c < 3; ++c) ulo[c] = std::min(ulo[c], R.lo[c]), uhi[c] = std::max(uhi[c], R.hi[c]);
        }
        bvh_.query(ulo, uhi, [&](Index T) {
          const TriRecord& RT = trec_[tri_slot_[T]];
          const bool t_refreshed = tflag_[T] != 0;
          for (Index k = g0; k < g1; ++k) {
            const Index t = refresh_t_[k];
            if (t == T || (t_refreshed && T < t)) continue;
            const TriRecord& Rt = trec_[tri_slot_[t]];
            if (overlap(Rt.lo, Rt.hi, RT.lo, RT.hi) && !share_vertex(Rt, RT)) emit(t, T);
          }
        }, qstacks_[me]);
        continue;
      }
      // A chunk of the neighbour lists: the element tests of vert_tri and of emit's edge pairs.
      const std::size_t c = q - ntrav;
      const std::size_t nvt = refreshed ? refresh_nbvt_.size() : nb_vt_.size();
      const std::size_t nee = refreshed ? refresh_nbee_.size() : nb_ee_.size();
      const std::size_t vt0 = nvt * c / kNeighbourChunks, vt1 = nvt * (c + 1) / kNeighbourChunks;
      const double* X = ref_x_.data();
      for (std::size_t k = vt0; k < vt1; ++k) {
        const std::size_t i = refreshed ? static_cast<std::size_t>(refresh_nbvt_[k]) : k;
        const Index v = nb_vt_[i][0], t = nb_vt_[i][1];
        test_vt(v, &X[3 * v], reach_[v], t, trec_[tri_slot_[t]]);
      }
      const std::size_t ee0 = nee * c / kNeighbourChunks, ee1 = nee * (c + 1) / kNeighbourChunks;
      for (std::size_t k = ee0; k < ee1; ++k) {
        const std::size_t i = refreshed ? static_cast<std::size_t>(refresh_nbee_[k]) : k;
        const Index e = nb_ee_[i][0], f = nb_ee_[i][1];
        const double *p0 = &X[3 * edges_[e][0]], *p1 = &X[3 * edges_[e][1]];
        const double er = std::max(reach_[edges_[e][0]], reach_[edges_[e][1]]);
        double elo[3], ehi[3];
        edge_box(p0, p1, er + half_gap, elo, ehi);
        test_ee(e, p0, p1, er, elo, ehi, f, &X[3 * edges_[f][0]], &X[3 * edges_[f][1]],
                std::max(reach_[edges_[f][0]], reach_[edges_[f][1]]));
      }
    }
  }
  for (std::size_t q = 0; q < ntasks; ++q) {
    vt_.insert(vt_.end(), task_vt_[q].begin(), task_vt_[q].end());
    ee_.insert(ee_.end(), task_ee_[q].begin(), task_ee_[q].end());
  }
  stats_.exact_tests += exact_count;
}

void SelfCollision::broad_phase(const double* x0_in, double gap, bool exact) {
  const bool par = nv_ >= kParallelMinVertices;
  if (x0_in != ref_x_.data()) std::memcpy(ref_x_.data(), x0_in, ref_x_.size() * sizeof(double));
#pragma omp parallel for schedule(static) if (par)
  for (Index k = 0; k < nt_; ++k) triangle_box(slot_tri_[k], gap);  // records in order
  bvh_.refit(tlo_.data(), thi_.data(), 0.0);

  vt_.clear();
  ee_.clear();
  traverse(gap, exact, false);
  std::fill(moved_.begin(), moved_.end(), 0.0);
  // The reference positions are the positions now: the frame F is the identity (its motion
  // over the step, f, stays: step_len_ does not change).
  for (int k = 0; k < 9; ++k) frame_R_[k] = k % 4 == 0 ? 1.0 : 0.0;
  frame_T_[0] = frame_T_[1] = frame_T_[2] = 0;
  frame_reset_ = true;
  have_candidates_ = true;
  stats_.rebuilt = true;
  ++stats_.rebuilds;
}

double SelfCollision::reach_for(Index i) const {
  const double th = opt_.thickness, s = step_len_[i];
  // Large steps (proximity_pairs' caller moves vertices by a thickness or more per step, so
  // the lists are renewed about every step whatever the reach): one displacement, not two,
  // which halves the boxes' growth and so the pairs listed (about 2.5 million at 128^2), and a
  // margin of at most th/4 (kLargeStepReachCap), which keeps the sheet's neighbours out.
  const double cap = large_steps_ ? kLargeStepReachCap : kReachCap;
  return std::max(kReachMin * th, (large_steps_ ? 1 : 2) * s) + std::min(kReachSteps * s, cap * th);
}

void SelfCollision::rebuild(const double* x0) {
  for (Index i = 0; i < nv_; ++i) reach_[i] = reach_for(i);
  broad_phase(x0, opt_.thickness, true);
}

void SelfCollision::update_candidates(const double* x0) {
  refresh_v_.clear();
  if (have_candidates_)
    for (Index i = 0; i < nv_; ++i)
      if (moved_[i] + step_len_[i] > reach_[i]) refresh_v_.push_back(i);
  // A refresh costs about ten box queries per vertex, several times a rebuild's cost per
  // vertex; a rebuild also restarts every vertex's allowance. Measured on the draped cloth at
  // 64^2 (one thread): refreshing up to 1/256 of the vertices, else rebuilding, cost 0.86 ms
  // per step against 1.05 ms (up to 1/64), 1.90 ms (up to 1/16) and 1.55 ms (always rebuild).
  // Large steps (baraff_witkin): a refresh of a few hundred vertices (the springs moved them
  // past the reach proximity_pairs set from the contact-free solve) costs far less than a
  // rebuild of lists that hold hundreds of pairs per vertex.
  const double fraction = large_steps_ ? std::max(opt_.refresh_fraction, kLargeStepRefreshFraction) : opt_.refresh_fraction;
  if (!have_candidates_ || static_cast<double>(refresh_v_.size()) > fraction * nv_)
    rebuild(x0);
  else if (!refresh_v_.empty())
    refresh(x0);
}

void SelfCollision::refresh(const double* x0) {
  // Invariant of the lists (every vertex i has a reference position X_i = ref_x_ and a reach
  // r_i with |x_i - X_i| <= r_i over the step): a pair outside them is at distance >= th +
  // r_a + r_b at the reference positions (r_a, r_b: the largest reach of each element's
  // vertices), so it cannot come within th. Pairs of the other vertices keep their reference
  // positions, reaches and distances: only the pairs involving a refreshed vertex change.
  const double th = opt_.thickness;
  refresh_t_.clear();
  refresh_e_.clear();
  refresh_group_.assign(1, 0);
  for (const Index v : refresh_v_) {
    vflag_[v] = 1;
    frame_reference(&x0[3 * v], &ref_x_[3 * v]);  // in the lists' frame: F(ref_x) = x0
    reach_[v] = reach_for(v);
    moved_[v] = 0;
    for (Index j = vt_off_[v]; j < vt_off_[v + 1]; ++j)
      if (!tflag_[vt_adj_[j]]) tflag_[vt_adj_[j]] = 1, refresh_t_.push_back(vt_adj_[j]);
    for (Index j = ve_off_[v]; j < ve_off_[v + 1]; ++j)
      if (!eflag_[ve_adj_[j]]) eflag_[ve_adj_[j]] = 1, refresh_e_.push_back(ve_adj_[j]);
    // The vertex's group ends here (none when all its triangles were in earlier groups).
    if (static_cast<Index>(refresh_t_.size()) > refresh_group_.back())
      refresh_group_.push_back(static_cast<Index>(refresh_t_.size()));
  }
  for (const Index t : refresh_t_) {
    triangle_box(t, th);
    bvh_.update_leaf(t, &tlo_[3 * t], &thi_[3 * t]);
  }
  // Drop the pairs that involve a refreshed vertex ...
  vt_.erase(std::remove_if(vt_.begin(), vt_.end(), [&](const Pair& p) { return vflag_[p.a] || tflag_[p.b]; }),
            vt_.end());
  ee_.erase(std::remove_if(ee_.begin(), ee_.end(), [&](const Pair& p) { return eflag_[p.a] || eflag_[p.b]; }),
            ee_.end());
  // ... and find them again: the leaf pairs of a rebuild that hold a refreshed triangle, found
  // by one hierarchy query per group (a refreshed vertex's triangles not in an earlier group,
  // with the union of their boxes), and in them the element pairs just dropped. A pair (vertex
  // v, triangle t) is met at the leaf pair (owner of v, t) and an edge pair at the pair of the
  // edges' owners, exactly once each as in a rebuild (a leaf pair of two refreshed triangles
  // from the lower index's group); a refreshed vertex or edge lies in a refreshed owner, so
  // every dropped pair has a refreshed leaf. As in a rebuild, the leaf pairs of triangles
  // sharing a vertex are skipped: their element pairs among the dropped
  // ones are taken from the neighbour lists, by element (each once: a pair of a refreshed
  // vertex from the vertex's entries, one of a refreshed triangle and a vertex that is not
  // from the triangle's, an edge pair from its lower refreshed edge).
  refresh_nbvt_.clear();
  refresh_nbee_.clear();
  for (const Index v : refresh_v_)
    for (Index j = nbv_off_[v]; j < nbv_off_[v + 1]; ++j) refresh_nbvt_.push_back(nbv_idx_[j]);
  for (const Index t : refresh_t_)
    for (Index j = nbt_off_[t]; j < nbt_off_[t + 1]; ++j)
      if (!vflag_[nb_vt_[nbt_idx_[j]][0]]) refresh_nbvt_.push_back(nbt_idx_[j]);
  for (const Index e : refresh_e_)
    for (Index j = nbe_off_[e]; j < nbe_off_[e + 1]; ++j) {
      const auto& pr = nb_ee_[nbe_idx_[j]];
      const Index other = pr[0] == e ? pr[1] : pr[0];
      if (!eflag_[other] || e < other) refresh_nbee_.push_back(nbe_idx_[j]);
    }
  traverse(th, true, true);
  for (const Index v : refresh_v_) vflag_[v] = 0;
  for (const Index t : refresh_t_) tflag_[t] = 0;
  for (const Index e : refresh_e_) eflag_[e] = 0;
  stats_.rebuilt = true;
  stats_.refreshed += static_cast<Index>(refresh_v_.size());
}

void SelfCollision::frame_reference(const double* y, double* X) const {
  const double r[3] = {y[0] - frame_T_[0], y[1] - frame_T_[1], y[2] - frame_T_[2]};
  for (int k = 0; k < 3; ++k) X[k] = frame_R_[k] * r[0] + frame_R_[3 + k] * r[1] + frame_R_[6 + k] * r[2];  // R^T r
}

namespace {

// w solving M w = b for the symmetric 3x3 M (xx, yy, zz, xy, xz, yz), or zero when M is
// singular for its size (the cloth's points on a line) or anything is not finite.
void solve_sym3(const double M[6], const double b[3], double w[3]) {
  const double a = M[0], e = M[1], i = M[2], bq = M[3], c = M[4], f = M[5];
  const double c0 = e * i - f * f, c1 = c * f - bq * i, c2 = bq * f - c * e;  // first row of the adjugate
  const double det = a * c0 + bq * c1 + c * c2;
  const double scale = (a + e + i) / 3;
  w[0] = w[1] = w[2] = 0;
  if (!(std::abs(det) > 1e-9 * scale * scale * scale) || !std::isfinite(det)) return;
  const double adj[3][3] = {{c0, c1, c2}, {c1, a * i - c * c, bq * c - a * f}, {c2, bq * c - a * f, a * e - bq * bq}};
  for (int k = 0; k < 3; ++k) w[k] = (adj[k][0] * b[0] + adj[k][1] * b[1] + adj[k][2] * b[2]) / det;
  if (!(std::isfinite(w[0]) && std::isfinite(w[1]) && std::isfinite(w[2]))) w[0] = w[1] = w[2] = 0;
}

// The rotation by angle |w| about w, row-major (the identity for w = 0).
void rotation(const double w[3], double Q[9]) {
  const double th = std::sqrt(selfcol::dot(w, w));
  for (int k = 0; k < 9; ++k) Q[k] = k % 4 == 0 ? 1.0 : 0.0;
  if (!(th > 0) || !std::isfinite(th)) return;
  const double a[3] = {w[0] / th, w[1] / th, w[2] / th};
  axis_angle_matrix(a, th, Q);
}

}  // namespace

void SelfCollision::advance_frame(const double (*part)[kFrameSums], Index n) {
  double S[kFrameSums] = {};
  for (int c = 0; c < kFrameChunks; ++c)
    for (int k = 0; k < kFrameSums; ++k) S[k] += part[c][k];
  const double inv = 1.0 / static_cast<double>(std::max<Index>(n, 1));
  for (double& v : S) v *= inv;
  const double c[3] = {S[0], S[1], S[2]};  // centroid of the step's start positions
  const double ub[3] = {frame_reset_ ? 0.0 : S[15], frame_reset_ ? 0.0 : S[16], frame_reset_ ? 0.0 : S[17]};
  const double db[3] = {S[18], S[19], S[20]};
  // Least squares: u - ub ~ w x (x0 - c), so J w = mean (x0 - c) x (u - ub) with J the
  // points' inertia about c, tr(C) 1 - C (C their covariance); the same for d.
  const double C[6] = {S[3] - c[0] * c[0], S[4] - c[1] * c[1], S[5] - c[2] * c[2],
                       S[6] - c[0] * c[1], S[7] - c[0] * c[2], S[8] - c[1] * c[2]};
  const double tr = C[0] + C[1] + C[2];
  const double J[6] = {tr - C[0], tr - C[1], tr - C[2], -C[3], -C[4], -C[5]};
  auto torque = [&](int at, const double* mean) {
    return std::array<double, 3>{S[at] - (c[1] * mean[2] - c[2] * mean[1]), S[at + 1] - (c[2] * mean[0] - c[0] * mean[2]),
                                 S[at + 2] - (c[0] * mean[1] - c[1] * mean[0])};
  };
  const std::array<double, 3> tu = torque(9, ub), td = torque(12, db);
  double wu[3] = {0, 0, 0}, wd[3];
  if (!frame_reset_) solve_sym3(J, tu.data(), wu);
  solve_sym3(J, td.data(), wd);
  // F' = Q (F - c) + c + ub + db, Q the rotation by wu + wd (after a rebuild F is the identity).
  const double w[3] = {wu[0] + wd[0], wu[1] + wd[1], wu[2] + wd[2]};
  double Q[9], R[9], T[3];
  rotation(w, Q);
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k)
      R[3 * r + k] = Q[3 * r] * frame_R_[k] + Q[3 * r + 1] * frame_R_[3 + k] + Q[3 * r + 2] * frame_R_[6 + k];
    T[r] = c[r] + ub[r] + db[r];
    for (int k = 0; k < 3; ++k) T[r] += Q[3 * r + k] * (frame_T_[k] - c[k]);
  }
  // R stays a rotation (Gram-Schmidt on its rows against rounding over many steps).
  auto normalise = [](double* v) {
    const double l = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int k = 0; k < 3; ++k) v[k] /= l;
  };
  normalise(&R[0]);
  const double p01 = R[0] * R[3] + R[1] * R[4] + R[2] * R[5];
  for (int k = 0; k < 3; ++k) R[3 + k] -= p01 * R[k];
  normalise(&R[3]);
  R[6] = R[1] * R[5] - R[2] * R[4], R[7] = R[2] * R[3] - R[0] * R[5], R[8] = R[0] * R[4] - R[1] * R[3];
  bool finite = true;
  for (int k = 0; k < 9; ++k) finite = finite && std::isfinite(R[k]);
  for (int k = 0; k < 3; ++k) finite = finite && std::isfinite(T[k]) && std::isfinite(db[k]) && std::isfinite(c[k]);
  if (!finite) return;  // a diverging step: the frame stays (any frame keeps the bounds valid)
  std::memcpy(frame_R_, R, sizeof R);
  std::memcpy(frame_T_, T, sizeof T);
  for (int k = 0; k < 3; ++k) spin_[k] = wd[k], drift_[k] = db[k], centre_[k] = c[k] + db[k];
}

bool SelfCollision::candidates_valid() const {
  if (!have_candidates_) return false;
  for (Index i = 0; i < nv_; ++i)
    if (moved_[i] + step_len_[i] > reach_[i]) return false;
  return true;
}

double SelfCollision::min_distance(const std::vector<double>& x, double within) {
  std::fill(reach_.begin(), reach_.end(), 0.0);
  broad_phase(x.data(), within, true);
  have_candidates_ = false;  // built for another reach: the next step rebuilds
  double m = within;
  for (const Pair& p : vt_) m = std::min(m, p.dist_ref);
  for (const Pair& p : ee_) m = std::min(m, p.dist_ref);
  return m;
}

void SelfCollision::candidate_pairs(const std::vector<double>& x, double inflate, std::vector<std::array<Index, 2>>& vt,
                                    std::vector<std::array<Index, 2>>& ee) {
  std::fill(reach_.begin(), reach_.end(), 0.0);
  broad_phase(x.data(), inflate, false);
  have_candidates_ = false;
  vt.clear();
  ee.clear();
  for (const Pair& p : vt_) vt.push_back({p.a, p.b});
  for (const Pair& p : ee_) ee.push_back({p.a, p.b});
  std::sort(vt.begin(), vt.end());
  std::sort(ee.begin(), ee.end());
}

void SelfCollision::candidate_lists(std::vector<std::array<Index, 2>>& vt, std::vector<std::array<Index, 2>>& ee) const {
  vt.clear();
  ee.clear();
  for (const Pair& p : vt_) vt.push_back({p.a, p.b});
  for (const Pair& p : ee_) ee.push_back({p.a, p.b});
  std::sort(vt.begin(), vt.end());
  std::sort(ee.begin(), ee.end());
}

void SelfCollision::proximity_pairs(const double* x, double within, std::vector<Proximity>& vt,
                                    std::vector<Proximity>& ee) {
  std::fill(reach_.begin(), reach_.end(), 0.0);
  broad_phase(x, within, true);
  have_candidates_ = false;
  vt.clear();
  ee.clear();
  for (const Pair& p : vt_) vt.push_back({p.a, p.b, p.dist_ref});
  for (const Pair& p : ee_) ee.push_back({p.a, p.b, p.dist_ref});
  auto by_ab = [](const Proximity& p, const Proximity& q) { return p.a < q.a || (p.a == q.a && p.b < q.b); };
  std::sort(vt.begin(), vt.end(), by_ab);
  std::sort(ee.begin(), ee.end(), by_ab);
}

bool SelfCollision::keep_outside(State& s, double h, const ColliderSet& colliders) {
  constexpr std::size_t kStackFrames = 16;  // placements on the stack; a collider beyond these (rare) is placed per query
  const auto& cols = colliders.colliders();
  const std::size_t nc = std::min(cols.size(), kStackFrames);
  Collider::Frame frames[kStackFrames];
  for (std::size_t c = 0; c < nc; ++c) frames[c] = cols[c].frame_at(s.time);
  bool moved = false;
  for (const Index v : touched_) {
    if (s.pinned[v]) continue;
    double y[3];
    for (int k = 0; k < 3; ++k) y[k] = x0_[3 * v + k] + d_[3 * v + k];
    bool in = false;
    for (std::size_t c = 0; c < cols.size(); ++c) {
      const Collider::Contact ct = c < nc ? cols[c].query(frames[c], y, 0.0) : cols[c].query(y, s.time);
      if (ct.distance >= 0) continue;
      // Onto the surface, inward velocity removed, no friction (the collider's own response had its turn).
      kernels::contact_respond(y, &s.v[3 * v], ct.distance, ct.normal.data(), ct.velocity.data(), 0.0, 0.0, h);
      in = true;
    }
    if (!in) continue;
    moved = true;
    touched_flag_[v] = 2;  // put back: freeze_pass(s, true) re-checks its pairs
    for (int k = 0; k < 3; ++k) d_[3 * v + k] = y[k] - x0_[3 * v + k];
    step_len_[v] = frame_step(&x0_[3 * v], &d_[3 * v]);
    max_growth_ = std::max(max_growth_, step_len_[v] - len0_[v]);
  }
  return moved;
}

namespace {
double relative_motion(bool vt, const Index idx[4], const double* p, const double* q);
}  // namespace

Index SelfCollision::freeze_pass(State& s, bool changed_only, const double* d_ref, double change) {
  // Fail-safe: every vertex of a pair that still collides returns to its start position and
  // stops. A pass ends when no collision remains; each pass freezes at least one moving vertex.
  // changed_only: the CCD passes ended clean, so only pairs with a vertex put back onto a
  // collider (keep_outside) or frozen here since have a path that was not checked.
  // d_ref (with changed_only): the d the near list was built with (nullptr: s.x - x0), and
  // `change` the largest |d - d_ref| of a vertex so far. A pair outside the near list was at
  // least the thickness apart over the path x0 + t d_ref; every vertex's path has moved by at
  // most `change` since, so while 2 change < thickness - tol no such pair meets within tol and
  // only the near pairs need the test (the CCD passes' rule). Freezing a vertex changes its d
  // to 0, by |d_ref| of it: counted in `change` before the next pass.
  const double th = opt_.thickness;
  const double tol = kCcdTolerance * th;
  Index frozen = 0;
  // The lists are complete on entry (the caller checked); only freezing changes a vertex's step.
  // A frozen vertex's d is 0, so in the lists' frame it moves by the frame's own motion over the
  // step, which can be far beyond its reach (a cloth falling as a whole gives its vertices reaches
  // of half a thickness): then the lists are renewed for the d of now before the next pass, and
  // every pair is tested (test AVertexTheFailSafeStopsInAClothFallingAsAWholeIsCheckedAgainstTheLayerAbove).
  bool left_reach = false;
  for (;;) {
    if (left_reach) {
      update_candidates(x0_.data());
      changed_only = false;
      left_reach = false;
    }
    const Index nvt = static_cast<Index>(vt_.size());
    Index found = 0;
    const Index before = frozen;
    const bool use_near = changed_only && 2 * change < th - tol;
    const Index count = use_near ? static_cast<Index>(near_.size()) : nvt + static_cast<Index>(ee_.size());
    {
      for (Index r = 0; r < count; ++r) {
        const Index q = use_near ? near_[r] : r;
        const bool vt = q < nvt;
        const Pair& p = vt ? vt_[q] : ee_[q - nvt];
        Index idx[4];
        pair_vertices(vt, p, idx);
        if (changed_only && !(touched_flag_[idx[0]] == 2 || touched_flag_[idx[1]] == 2 || touched_flag_[idx[2]] == 2 ||
                              touched_flag_[idx[3]] == 2 || frozen_[idx[0]] || frozen_[idx[1]] || frozen_[idx[2]] ||
                              frozen_[idx[3]]))
          continue;
        const double motion = vt ? step_len_[idx[0]] + std::max({step_len_[idx[1]], step_len_[idx[2]], step_len_[idx[3]]})
                                 : std::max(step_len_[idx[0]], step_len_[idx[1]]) + std::max(step_len_[idx[2]], step_len_[idx[3]]);
        if (motion == 0) continue;
        double m[4];
        for (int i = 0; i < 4; ++i) m[i] = moved_[idx[i]] + step_len_[idx[i]];
        const double mv = vt ? m[0] + std::max({m[1], m[2], m[3]}) : std::max(m[0], m[1]) + std::max(m[2], m[3]);
        if (p.dist_ref - mv > tol) continue;
        if (p.dist_ref - relative_motion(vt, idx, x0_.data(), ref_x_.data()) -
                relative_motion(vt, idx, d_.data(), nullptr) > tol)
          continue;  // relative motion (see resolve()): cannot meet within the step
        double t;
        if (!pair_ccd(vt, idx, tol, t)) continue;
        ++found;
        for (int i = 0; i < 4; ++i) {
          const Index v = idx[i];
          if (s.pinned[v] || frozen_[v]) continue;
          frozen_[v] = 1;
          ++frozen;
          {
            double c2 = 0;
            for (int k = 0; k < 3; ++k) {
              const double c = d_ref ? d_ref[3 * v + k] : s.x[3 * v + k] - x0_[3 * v + k];
              c2 += c * c;
            }
            change = std::max(change, std::sqrt(c2));
          }
          inv_mass_[v] = 0;
          for (int k = 0; k < 3; ++k) {
            d_[3 * v + k] = 0;
            s.v[3 * v + k] = 0;
          }
          step_len_[v] = frame_step(&x0_[3 * v], &d_[3 * v]);
          left_reach |= moved_[v] + step_len_[v] > reach_[v];
        }
      }
    }
    if (found == 0) break;
    if (frozen == before) break;  // only pinned vertices still move: a prescribed pin motion drives it
  }
  return frozen;
}

namespace {
// Largest |u_a - u_b| over a vertex a of one side and b of the other (vertex-triangle: {0} and
// {1, 2, 3}; edge-edge: {0, 1} and {2, 3}), u = p - q per vertex (q = nullptr: u = p).
double relative_motion(bool vt, const Index idx[4], const double* p, const double* q) {
  double u[4][3];
  for (int i = 0; i < 4; ++i)
    for (int k = 0; k < 3; ++k) u[i][k] = p[3 * idx[i] + k] - (q ? q[3 * idx[i] + k] : 0.0);
  double m = 0;
  for (int a = 0; a < (vt ? 1 : 2); ++a)
    for (int b = vt ? 1 : 2; b < 4; ++b) {
      double r[3];
      selfcol::sub(u[a], u[b], r);
      m = std::max(m, selfcol::dot(r, r));
    }
  return std::sqrt(m);
}
}  // namespace

void SelfCollision::resolve(State& s, double h, const ColliderSet* colliders) {
  const auto t_call = Clock::now();
  resolve_step(s, h, colliders);
  totals_.steps += 1;
  totals_.resolve_seconds += seconds_since(t_call);
  totals_.broad_seconds += stats_.broad_seconds;
  totals_.narrow_seconds += stats_.narrow_seconds;
  totals_.response_seconds += stats_.response_seconds;
  totals_.proximity += stats_.proximity;
  totals_.ccd_collisions += stats_.ccd_collisions;
  totals_.frozen += stats_.frozen;
  totals_.rebuilds += stats_.rebuilds;
  totals_.refreshed += stats_.refreshed;
}

void SelfCollision::resolve_step(State& s, double h, const ColliderSet* colliders) {
  stats_ = SelfCollisionStats{};
  for (const Index v : touched_) touched_flag_[v] = 0;
  touched_.clear();
  auto t0 = Clock::now();
  const Index n = nv_;
  const double th = opt_.thickness;
  double* x = s.x.data();
  // One pass over the vertices. The candidate lists
  // are reused while every vertex stays within its reach of the positions they were built at
  // (motion since then plus this step's displacement); otherwise they are rebuilt.
  // Motions are measured in the lists' frame (see the header): a sheet moving or turning as a
  // whole keeps its lists. The frame's sums per fixed chunk, added in chunk order, so the next
  // frame does not depend on the thread count.
  int invalid = have_candidates_ ? 0 : 1;
  // Per chunk: sums of x0 (3), x0 x0^T (6: xx, yy, zz, xy, xz, yz), x0 x u (3), x0 x d (3), u
  // (3) and d (3), u = x0 - F(ref_x): advance_frame() fits the next frame to them.
  double part[kFrameChunks][kFrameSums];
  const double kappa = frame_stretch();
#pragma omp parallel for reduction(+ : invalid) schedule(static) if (n >= kParallelMinVertices)
  for (int c = 0; c < kFrameChunks; ++c) {
    double sum[kFrameSums] = {};
    const Index i1 = static_cast<Index>(static_cast<std::int64_t>(n) * (c + 1) / kFrameChunks);
    for (Index i = static_cast<Index>(static_cast<std::int64_t>(n) * c / kFrameChunks); i < i1; ++i) {
      const double* a = &x0_[3 * i];
      double u[3], dk[3], au[3], ad[3];
      for (int k = 0; k < 3; ++k) d_[3 * i + k] = dk[k] = x[3 * i + k] - a[k];
      frame_residual(i, a, u);
      step_len_[i] = len0_[i] = frame_step(a, dk);
      moved_[i] = kappa * std::sqrt(selfcol::dot(u, u));
      invalid += moved_[i] + step_len_[i] > reach_[i] ? 1 : 0;
      inv_mass_[i] = s.inv_mass[i];
      frozen_[i] = 0;
      sum[0] += a[0], sum[1] += a[1], sum[2] += a[2];
      sum[3] += a[0] * a[0], sum[4] += a[1] * a[1], sum[5] += a[2] * a[2];
      sum[6] += a[0] * a[1], sum[7] += a[0] * a[2], sum[8] += a[1] * a[2];
      selfcol::cross(a, u, au);
      selfcol::cross(a, dk, ad);
      for (int k = 0; k < 3; ++k) sum[9 + k] += au[k], sum[12 + k] += ad[k], sum[15 + k] += u[k], sum[18 + k] += dk[k];
    }
    for (int k = 0; k < kFrameSums; ++k) part[c][k] = sum[k];
  }
  frame_reset_ = false;
  if (invalid > 0) update_candidates(x0_.data());
  stats_.candidates_vt = static_cast<Index>(vt_.size());
  stats_.candidates_ee = static_cast<Index>(ee_.size());
  stats_.broad_seconds = seconds_since(t0);
  t0 = Clock::now();

  // Narrow phase (proximity at the start positions): a pair can only come within the
  // thickness if its distance at the broad phase, less the motion since and during the step,
  // is below it (distance is 1-Lipschitz in each vertex position).
  // A vertex stays within moved_ + step_len_ of its reference position over the step, so each
  // element stays within the largest of these among its vertices (a tighter bound than the
  // largest motion since the reference plus the largest step).
  const auto bound = [&](bool vt, const Index idx[4]) {
    double m[4];
    for (int i = 0; i < 4; ++i) m[i] = moved_[idx[i]] + step_len_[idx[i]];
    if (vt) return m[0] + std::max({m[1], m[2], m[3]});
    return std::max(m[0], m[1]) + std::max(m[2], m[3]);
  };
  const auto step_bound = [&](bool vt, const Index idx[4]) {
    if (vt) return step_len_[idx[0]] + std::max({step_len_[idx[1]], step_len_[idx[2]], step_len_[idx[3]]});
    return std::max(step_len_[idx[0]], step_len_[idx[1]]) + std::max(step_len_[idx[2]], step_len_[idx[3]]);
  };
  const Index nvt = static_cast<Index>(vt_.size());
  // The near list over the current lists, with d as it is now (also after the lists were
  // renewed during the CCD passes: then with a snapshot of d, so that the passes can bound the
  // change of the responses since).
  const auto build_near = [&] {
    const Index nvt_now = static_cast<Index>(vt_.size()), np = nvt_now + static_cast<Index>(ee_.size());
    near_flag_.resize(np);
#pragma omp parallel for schedule(static) if (np >= 4 * kParallelMinVertices)
    for (Index q = 0; q < np; ++q) {
      const bool vt = q < nvt_now;
      const Pair& p = vt ? vt_[q] : ee_[q - nvt_now];
      Index idx[4];
      pair_vertices(vt, p, idx);
      // Tighter from relative motion, as in proximity_pairs: the distance moves by at most the
      // largest |u_a - u_b| (a vertex of each element), u the motion since the reference, plus
      // that of the step's d (a sheet moving as a whole has most pairs near by the bound above).
      near_flag_[q] = p.dist_ref - bound(vt, idx) < th &&
                      p.dist_ref - relative_motion(vt, idx, x0_.data(), ref_x_.data()) -
                              relative_motion(vt, idx, d_.data(), nullptr) < th;
    }
    near_.clear();
    for (Index q = 0; q < np; ++q)
      if (near_flag_[q]) near_.push_back(q);
  };
  build_near();
  stats_.near = static_cast<Index>(near_.size());
  near_dist_.assign(near_.size(), -1.0);
  near_clean_.assign(near_.size(), 0);
  vstamp_.assign(nv_, 0);
  ccd_clock_ = 0;
  max_growth_ = 0;
  responded_ = false;
  Index proximity = 0;
  for (std::size_t r = 0; r < near_.size(); ++r) {
    if (!opt_.repulsion) break;
    const Index q = near_[r];
    const bool vt = q < nvt;
    const Pair& p = vt ? vt_[q] : ee_[q - nvt];
    Index idx[4];
    pair_vertices(vt, p, idx);
    double w[4], nrm[3];
    const double dist = pair_distance(vt, idx, x0_.data(), w, nrm);
    near_dist_[r] = dist;
    double dn = 0;
    for (int i = 0; i < 4; ++i)
      for (int k = 0; k < 3; ++k) dn += w[i] * d_[3 * idx[i] + k] * nrm[k];
    const double gap = dist + dn;  // linearised distance at the end of the step
    const double target = dist < th ? dist + kRepulsionFraction * (th - dist) : th;
    if (dist >= th && gap >= target) continue;
    if (respond(idx, w, nrm, std::max(0.0, target - gap), h, s)) ++proximity;
  }
  stats_.proximity = proximity;
  stats_.narrow_seconds = seconds_since(t0);
  t0 = Clock::now();

  // CCD impulse iterations (Gauss-Seidel over the pairs), then the fail-safe.
  const double tol = kCcdTolerance * th;
  bool clean = false;
  // Pairs outside the near list were farther than the thickness plus their motion; responses
  // lengthen displacements by at most max_growth_, so the list stays complete for CCD while
  // 2 max_growth_ < thickness - tol (after a new traversal, all pairs are visited).
  bool near_valid = true, near_renewed = false;
  // The largest change of a touched vertex's d (at least `from`): since the near list's snapshot
  // of d after a renewal, else since the start of the step (x0 + d against the responses' x).
  auto largest_change = [&](double from) {
    for (const Index v : touched_) {
      double c2 = 0;
      for (int k = 0; k < 3; ++k) {
        const double c = near_renewed ? d_[3 * v + k] - d_near_[3 * v + k] : x0_[3 * v + k] + d_[3 * v + k] - x[3 * v + k];
        c2 += c * c;
      }
      from = std::max(from, std::sqrt(c2));
    }
    return from;
  };
  for (int it = 0; it < opt_.ccd_iterations && !clean; ++it) {
    if (responded_ && !candidates_valid()) {
      update_candidates(x0_.data());
      // New lists: a near list over them from the d of now (its start distances are not known).
      build_near();
      near_dist_.assign(near_.size(), -1.0);
      near_clean_.assign(near_.size(), 0);
      d_near_.assign(d_.begin(), d_.end());
      near_renewed = true;
    }
    ++stats_.ccd_iterations;
    Index hits = 0;
    const Index nvt_now = static_cast<Index>(vt_.size());
    // Responses change d by at most max_change (per vertex, |d - d at the start|), so relative
    // displacements by at most 2 max_change (max_growth_ <= max_change).
    // After a renewal of the near list: the change since its snapshot of d.
    const double max_change = largest_change(0.0);
    const bool use_near = near_valid && 2 * (near_renewed ? max_change : std::max(max_growth_, max_change)) < th - tol;
    const Index count = use_near ? static_cast<Index>(near_.size()) : nvt_now + static_cast<Index>(ee_.size());
    for (Index r = 0; r < count; ++r) {
      const Index q = use_near ? near_[r] : r;
      const bool vt = q < nvt_now;
      const Pair& p = vt ? vt_[q] : ee_[q - nvt_now];
      {
        Index idx[4];
        pair_vertices(vt, p, idx);
        // A near pair found clean by an earlier pass stays clean until an impulse changes the d
        // of one of its vertices: its test depends on x0 and on those d only.
        if (use_near && near_clean_[r] > std::max({vstamp_[idx[0]], vstamp_[idx[1]], vstamp_[idx[2]], vstamp_[idx[3]]}))
          continue;
        const auto clean_now = [&] {
          if (use_near) near_clean_[r] = ccd_clock_ + 1;
        };
        if (p.dist_ref - bound(vt, idx) > tol) {
          clean_now();
          continue;
        }
        // Tighter for a near pair: its distance at the step's start less the motion in the step
        // (d as the responses have changed it so far), absolute or relative (max |d_a - d_b|).
        if (use_near && near_dist_[r] >= 0 &&
            near_dist_[r] - std::min(step_bound(vt, idx), relative_motion(vt, idx, d_.data(), nullptr)) > tol) {
          clean_now();
          continue;
        }
        // Over the whole lists: the relative bound of the near filter, with d as it is now.
        if (!use_near && p.dist_ref - relative_motion(vt, idx, x0_.data(), ref_x_.data()) -
                                 relative_motion(vt, idx, d_.data(), nullptr) > tol)
          continue;
        ++stats_.ccd_tests;
        double t;
        if (!pair_ccd(vt, idx, tol, t)) {
          clean_now();
          continue;
        }
        ++hits;
        // Normal and weights at the collision time, oriented from the start-of-step side.
        double xt[4][3], w[4], nrm[3];
        for (int i = 0; i < 4; ++i)
          for (int k = 0; k < 3; ++k) xt[i][k] = x0_[3 * idx[i] + k] + t * d_[3 * idx[i] + k];
        double a[3], b[3];
        if (vt) {
          double bc[3];
          selfcol::point_triangle_distance(xt[0], xt[1], xt[2], xt[3], bc);
          w[0] = 1, w[1] = -bc[0], w[2] = -bc[1], w[3] = -bc[2];
          selfcol::sub(xt[2], xt[1], a);
          selfcol::sub(xt[3], xt[1], b);
        } else {
          double ss, tt;
          selfcol::segment_segment_distance(xt[0], xt[1], xt[2], xt[3], ss, tt);
          w[0] = -(1 - ss), w[1] = -ss, w[2] = 1 - tt, w[3] = tt;
          selfcol::sub(xt[1], xt[0], a);
          selfcol::sub(xt[3], xt[2], b);
        }
        selfcol::cross(a, b, nrm);
        double len = std::sqrt(selfcol::dot(nrm, nrm));
        double sep0 = 0, dn = 0;
        if (!(len > 1e-12 * std::sqrt(selfcol::dot(a, a) * selfcol::dot(b, b)))) {
          // Parallel edges (or a degenerate triangle): the direction between the closest points at the start.
          double ww[4];
          pair_distance(vt, idx, x0_.data(), ww, nrm);
          len = 1;
        } else {
          for (int k = 0; k < 3; ++k) nrm[k] /= len;
        }
        for (int i = 0; i < 4; ++i)
          for (int k = 0; k < 3; ++k) {
            sep0 += w[i] * x0_[3 * idx[i] + k] * nrm[k];
            dn += w[i] * d_[3 * idx[i] + k] * nrm[k];
          }
        if (sep0 < 0 || (sep0 == 0 && dn > 0)) {
          for (int k = 0; k < 3; ++k) nrm[k] = -nrm[k];
          sep0 = -sep0;
          dn = -dn;
        }
        const double dpos = std::max(kCcdSeparation * th - (sep0 + dn), 0.05 * th);
        respond(idx, w, nrm, dpos, h, s);
        ++ccd_clock_;
        for (int i = 0; i < 4; ++i) vstamp_[idx[i]] = ccd_clock_;
      }
    }
    stats_.ccd_collisions += hits;
    clean = hits == 0;
  }
  // The response may have pushed cloth resting on a collider into it (the layers above press
  // it down): put it back before the fail-safe, which then sees the corrected step and, where
  // that collides, restores the step's start (outside the colliders when the step began so).
  const bool projected = colliders && !colliders->empty() && !touched_.empty() && keep_outside(s, h, *colliders);
  if (!clean || projected) {
    bool all_pairs = !clean;
    if (!candidates_valid()) {
      update_candidates(x0_.data());
      all_pairs = true;  // pairs new to the lists were not in the CCD passes
    }
    // The largest change of a vertex's d since the near list's d (see freeze_pass).
    const double change = largest_change(near_renewed ? 0.0 : max_growth_);
    stats_.frozen = freeze_pass(s, !all_pairs, near_renewed ? d_near_.data() : nullptr, change);
    responded_ = true;
  }
  if (responded_)
    for (Index i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) x[3 * i + k] = x0_[3 * i + k] + d_[3 * i + k];
  // The next step's frame, fitted to the motion since the lists' reference (none when the
  // lists were rebuilt in this step) and to this step's displacement, which also predicts the
  // next step's.
  advance_frame(part, n);
  stats_.response_seconds = seconds_since(t0);
}

}  // namespace loom

namespace loom {

void SelfCollision::proximity_pairs(const double* x, const double* d, std::vector<ProximityPair>& out) {
  const auto t_call = Clock::now();
  const int rebuilds = stats_.rebuilds;
  const Index refreshed = stats_.refreshed;
  find_pairs(x, d, out);
  totals_.search_seconds += seconds_since(t_call);
  totals_.rebuilds += stats_.rebuilds - rebuilds;
  totals_.refreshed += stats_.refreshed - refreshed;
}

void SelfCollision::find_pairs(const double* x, const double* d, std::vector<ProximityPair>& out) {
  out.clear();
  large_steps_ = true;
  const double th = opt_.thickness;
  // The same lists as resolve(): kept while every vertex stays within its reach over the
  // motion since the lists' reference positions plus the predicted step d; otherwise refreshed
  // or rebuilt at x (update_candidates), and resolve() after the step reuses them.
  int invalid = have_candidates_ ? 0 : 1;
  const double kappa = frame_stretch();
  for (Index i = 0; i < nv_; ++i) {
    step_len_[i] = frame_step(&x[3 * i], &d[3 * i]);
    moved_[i] = frame_moved(i, &x[3 * i], kappa);
    invalid += moved_[i] + step_len_[i] > reach_[i] ? 1 : 0;
  }
  if (invalid > 0) {
    const auto t_renew = Clock::now();
    update_candidates(x);
    totals_.search_broad_seconds += seconds_since(t_renew);
  }
  const Index nvt = static_cast<Index>(vt_.size()), npairs = nvt + static_cast<Index>(ee_.size());
  for (Index q = 0; q < npairs; ++q) {
    const bool vt = q < nvt;
    const Pair& p = vt ? vt_[q] : ee_[q - nvt];
    Index idx[4];
    pair_vertices(vt, p, idx);
    double step, since;
    if (vt) {
      step = step_len_[idx[0]] + std::max({step_len_[idx[1]], step_len_[idx[2]], step_len_[idx[3]]});
      since = moved_[idx[0]] + std::max({moved_[idx[1]], moved_[idx[2]], moved_[idx[3]]});
    } else {
      step = std::max(step_len_[idx[0]], step_len_[idx[1]]) + std::max(step_len_[idx[2]], step_len_[idx[3]]);
      since = std::max(moved_[idx[0]], moved_[idx[1]]) + std::max(moved_[idx[2]], moved_[idx[3]]);
    }
    if (p.dist_ref - since - step >= th) continue;  // distance is 1-Lipschitz in each vertex
    // Tighter, from relative motion: two elements whose vertices move by m_a (one side) and m_b
    // (other side) change their distance by at most max |m_a - m_b| (a convex combination of
    // these differences moves the closest points), so a falling sheet keeps its bound.
    const double step_rel = std::min(step, relative_motion(vt, idx, d, nullptr));
    if (p.dist_ref - std::min(since, relative_motion(vt, idx, x, ref_x_.data())) - step_rel >= th) continue;
    ProximityPair r;
    r.vt = vt;
    r.distance = pair_distance(vt, idx, x, r.w, r.normal);
    if (r.distance - step_rel >= th) continue;
    for (int i = 0; i < 4; ++i) r.v[i] = idx[i];
    out.push_back(r);
  }
}

}  // namespace loom
