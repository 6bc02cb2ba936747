// ParaView output: one VTK XML UnstructuredGrid file (.vtu) per written frame and a ParaView
// collection (.pvd) listing the frames with their times. Both are the plain documented VTK
// XML formats (https://docs.vtk.org/en/latest/design_documents/VTKFileFormats.html), written
// by hand: libvtk9-dev would pull in ~200 MB of packages for two small text formats.
#pragma once

#include <array>
#include <span>
#include <string>
#include <vector>

#include "loom/common.hpp"
#include "loom/mesh.hpp"

namespace loom {

/// Writes frame_NNNNN.vtu files and keeps run.pvd up to date. Each .vtu holds the triangles
/// (VTK_TRIANGLE = 5), the positions (Float64, the shortest decimal that reads back as the same
/// double), the time as FieldData "TimeValue", and per-vertex point data:
///   - "strain": the largest |l / l0 - 1| over the mesh edges at the vertex (l0: rest length);
///   - "velocity" (3 components, m/s), when velocities are given.
class VtkSeriesWriter {
 public:
  /// dir: the output folder; mesh: topology and rest shape (for strain). uvs: write the mesh's
  /// material coordinates as the point data `uv` (the texture coordinates, TCoords) when it has
  /// one uv per vertex and no seam (uv_seam_free); a mesh with seams gets no `uv` array.
  VtkSeriesWriter(const std::string& dir, const Mesh& mesh, bool uvs = false);

  /// True when the frames carry the `uv` array.
  bool writes_uvs() const { return uvs_; }

  /// Keep the entries of an earlier run's run.pvd with frame <= last_frame (for --resume).
  /// Returns how many were kept.
  int adopt_existing(int last_frame);

  /// Write frame_NNNNN.vtu (atomically) and rewrite run.pvd (atomically) with it added.
  /// v may be empty (no velocity array). gap: per vertex, the signed distance to the nearest
  /// collider's offset surface (m), written as `collider_gap` with a `contact` flag (1 where
  /// gap <= kContactGap); empty when the scene has no colliders.
  void write_frame(int frame, double time, std::span<const double> x, std::span<const double> v,
                   std::span<const double> gap = {});

  /// The .vtu text of one frame (also used by tests).
  std::string vtu_text(double time, std::span<const double> x, std::span<const double> v,
                       std::span<const double> gap = {});

  /// A vertex within this distance of a collider's offset surface (or inside it) counts as in
  /// contact in the `contact` array: contact resolution leaves resting vertices on the surface
  /// to rounding, far below a micrometre.
  static constexpr double kContactGap = 1e-6;

 private:
  std::string pvd_text() const;

  std::string dir_;
  const Mesh& mesh_;
  bool uvs_ = false;
  std::vector<std::array<Index, 2>> edges_;
  std::vector<double> rest_length_;
  std::vector<double> strain_;  // work array, n
  std::vector<double> contact_;  // work array, n
  struct Entry {
    int frame;
    double time;
  };
  std::vector<Entry> entries_;
};

/// True when the mesh has one uv per vertex and every triangle corner has its vertex's uv (no UV
/// seam), so that one texture coordinate per point describes it exactly: a generated grid, or an
/// OBJ whose `vt` never differ at a vertex. False without uvs.
bool uv_seam_free(const Mesh& mesh);

/// "frame_NNNNN.vtu" (the name the series uses for a frame).
std::string vtu_frame_name(int frame);

}  // namespace loom
