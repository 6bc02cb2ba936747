// Exact triangle-triangle intersection check, independent of any collision code.
//
// What counts as intersecting: two CLOSED triangles (boundary included) that share at
// least one point. Touching counts (a vertex on the other triangle, two edges crossing or
// overlapping, coplanar triangles that overlap or touch along an edge). Degenerate
// triangles (collinear or repeated vertices) are treated as the segments or points they
// are. Pairs that share a mesh vertex (neighbours across an edge or a vertex) are never
// counted: they always touch.
//
// Exactness: every decision is the sign of an orientation determinant (orient3d, or orient2d
// in an axis projection on which the triangle's plane projects one-to-one), evaluated in
// double precision with a forward error bound and, when the bound does not decide, exactly
// with floating-point expansions (Shewchuk's arithmetic). The answer is therefore the exact
// answer for the double coordinates given, whatever the configuration.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <span>
#include <vector>

#include "loom/common.hpp"
#include "loom/mesh.hpp"

namespace loom {

namespace exact {
/// Sign (-1, 0, +1) of ((b-a) x (c-a)) . (d-a): +1 when d lies on the side of the plane
/// through a, b, c that the normal of the counter-clockwise triangle abc points to.
int orient3d(const double* a, const double* b, const double* c, const double* d);
/// Sign of det[b-a, c-a] of the 2D points (the coordinates u, v of each point are p[u], p[v]).
int orient2d(const double* a, const double* b, const double* c, int u, int v);
}  // namespace exact

/// Exact test: do the closed triangles (a0, a1, a2) and (b0, b1, b2) share a point?
bool triangles_intersect(const double* a0, const double* a1, const double* a2, const double* b0, const double* b1,
                         const double* b2);

/// Number of intersecting non-adjacent triangle pairs of `mesh` (topology) at positions x
/// (3 per vertex; the mesh's own positions when x is empty). When `pairs` is given, it
/// receives the pairs (t1 < t2), sorted. Broad phase: a uniform grid over the triangles'
/// bounding boxes, each overlapping pair tested once.
std::size_t count_intersecting_pairs(const Mesh& mesh, std::span<const double> x,
                                     std::vector<std::array<Index, 2>>* pairs = nullptr);

/// Distances between the elements of a cloth (loom check --distance), written for the check and
/// independent of the collision code, like the intersection test above. Each result is the same
/// double whatever the order of the vertices and of the two elements.
namespace distance {
/// Distance from point p to the closed segment ab (a point when a == b).
double point_segment(const double* p, const double* a, const double* b);
/// Distance from point p to the closed triangle abc (also when it is degenerate).
double point_triangle(const double* p, const double* a, const double* b, const double* c);
/// Distance between the closed segments p0p1 and q0q1 (also parallel or degenerate ones).
double segment_segment(const double* p0, const double* p1, const double* q0, const double* q1);
}  // namespace distance

/// The closest approach of two non-adjacent elements of a cloth: a vertex and a triangle that
/// does not have it as a corner, or two edges that share no vertex (the pairs self-collision
/// keeps a thickness apart, and whose smallest distance in the cloth as built bounds the
/// thickness a scene may ask for).
struct ClosestApproach {
  double distance = INFINITY;    ///< INFINITY: no pair closer than the search distance
  bool vertex_triangle = true;   ///< the pair: vertex v[0] and triangle (v[1], v[2], v[3]), or
  std::array<Index, 4> v{-1, -1, -1, -1};  ///< ... edges (v[0], v[1]) and (v[2], v[3]) (each i < j)
};

/// The closest approach of non-adjacent elements of `mesh` at positions x (the mesh's own when
/// empty), among the pairs closer than `within` (> 0): distance INFINITY when there is none.
/// Broad phase: the grid of count_intersecting_pairs over the triangles' boxes grown by
/// within / 2, each overlapping triangle pair once, its non-adjacent element pairs measured.
/// The distance and the pair do not depend on the thread count.
ClosestApproach closest_approach(const Mesh& mesh, std::span<const double> x, double within);

}  // namespace loom
