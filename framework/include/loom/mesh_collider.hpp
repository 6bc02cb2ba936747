// A rigid triangle-mesh obstacle for colliders (`type: mesh`): the mesh in its body frame,
// a bounding-volume hierarchy built once, and the signed distance to it.
//
// Sign: from the angle-weighted pseudo-normal of the nearest feature (Baerentzen & Aanaes
// 2005): the face normal in a face's interior, the mean of the two face normals on an edge,
// the angle-weighted mean of the incident face normals at a vertex. For a CLOSED mesh this
// is exactly inside (< 0) / outside (> 0); faces wound clockwise seen from outside (negative
// volume) are flipped on load. For an OPEN mesh (a table top) the front, the side the
// counter-clockwise face normals point to, is outside: a point behind the surface counts as
// inside and is pushed to the front.
#pragma once

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "loom/collider.hpp"
#include "loom/common.hpp"
#include "loom/kernels/mesh_query.hpp"

namespace loom {

class MeshBody {
 public:
  /// Read an OBJ collider mesh: positions * scale + offset. Throws InputError naming the
  /// file, the line and the fix for a missing or empty file, NaN/Inf coordinates, degenerate
  /// faces and non-manifold meshes (an edge with more than two faces, or two faces
  /// traversing an edge in the same direction).
  static std::shared_ptr<MeshBody> load(const std::string& path, double scale, const std::array<double, 3>& offset);
  /// From vertex positions and triangles (tests); `source` names it in messages.
  static std::shared_ptr<MeshBody> build(std::vector<double> positions, std::vector<Index> triangles,
                                         const std::string& source, const std::vector<int>& face_lines = {});

  /// point: nearest point on the mesh; normal: pseudo-normal of the nearest feature (unit,
  /// outward); distance: unsigned; face.
  using Nearest = kernels::MeshNearest;
  /// Nearest point on the mesh to p (body frame). No allocation.
  Nearest nearest(const double p[3]) const;
  /// Signed distance (< 0 inside / behind) and the outward unit normal at p.
  double signed_distance(const double p[3], double normal[3], double point[3]) const;
  /// The same for callers that need the answer only below `cutoff` (> 0): a result below
  /// cutoff is exact (normal and point too); a result >= cutoff is a lower bound of a positive
  /// distance (normal and point then unspecified). Far points are cheap: the search skips every
  /// part of the hierarchy farther than cutoff, and on a closed mesh a point outside the
  /// bounding box by cutoff or more is answered from the box alone.
  double signed_distance(const double p[3], double normal[3], double point[3], double cutoff) const;

  bool closed() const { return closed_; }
  Index num_vertices() const { return static_cast<Index>(x_.size() / 3); }
  Index num_triangles() const { return static_cast<Index>(tri_.size() / 3); }
  const std::vector<double>& positions() const { return x_; }
  const std::vector<Index>& triangles() const { return tri_; }
  const std::array<double, 3>& box_center() const { return center_; }
  const std::string& source() const { return source_; }

  /// The geometry as plain arrays (the queries run on these, loom/kernels/mesh_query.hpp; the
  /// CUDA backend uploads the same arrays once).
  using Node = kernels::MeshNode;
  const std::vector<double>& face_normals() const { return face_n_; }
  const std::vector<double>& vertex_normals() const { return vert_n_; }
  const std::vector<double>& edge_normals() const { return edge_n_; }
  const std::vector<Node>& nodes() const { return nodes_; }
  const std::vector<Index>& leaf_order() const { return order_; }
  /// Pointers into this body's arrays.
  kernels::MeshView view() const;

 private:
  Index build_node(Index begin, Index end, std::vector<double>& centroid);

  std::vector<double> x_;
  std::vector<Index> tri_;
  std::vector<double> face_n_;   ///< 3 per face
  std::vector<double> vert_n_;   ///< 3 per vertex (angle weighted)
  std::vector<double> edge_n_;   ///< 9 per face: edge k = (v_k, v_k+1)
  std::vector<Node> nodes_;
  std::vector<Index> order_;
  std::array<double, 3> center_{0, 0, 0};
  bool closed_ = false;
  std::string source_;
};

/// A mesh collider's placement at a frame as the query's plain data (loom/kernels/mesh_query.hpp):
/// what Collider::query runs on the CPU and the CUDA backend passes to its kernels.
kernels::MeshPlacement mesh_placement(const Collider& c, const Collider::Frame& f);

}  // namespace loom
