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

}  // namespace loom
