// The triangles `loom render` draws for the colliders are where contact puts them.
#include <gtest/gtest.h>

#include <cmath>

#include "loom/collider_geometry.hpp"

namespace {
loom::ColliderSet parse(const std::string& yaml) {
  return loom::ColliderSet::parse(loom::Params::from_string(yaml, "scene.yaml").child("colliders"),
                                  LOOM_SOURCE_DIR "/scenes");
}
}  // namespace

TEST(ColliderGeometry, TrianglesLieOnTheContactSurfacesAtTheFrameTime) {
  const auto set = parse(
      "colliders:\n"
      "  - {type: sphere, center: [0, 1, 0], radius: 0.5, thickness: 0.01, motion: {type: translate, velocity: [1, 0, 0]}}\n"
      "  - {type: plane, point: [0, -1, 0], normal: [0, 1, 1], motion: {type: rotate, axis: [1, 0, 0], angular_velocity: 0.5}}\n"
      "  - {type: mesh, obj: meshes/icosphere1.obj, scale: 0.2, offset: [2, 0, 0], pivot: [2, 0.3, 0], thickness: 0.02,\n"
      "     motion: {type: keyframes, axis: [0, 0, 1], keys: [{t: 0, translate: [0, 0, 0], angle: 0},\n"
      "                                                     {t: 1, translate: [0, 1, 0], angle: 1.2}]}}\n");
  const double t = 0.7, focus[3] = {0.3, 0.2, 0.1};
  std::vector<float> pos, nrm;
  loom::collider_triangles(set, t, focus, 3.0, pos, nrm);
  ASSERT_EQ(pos.size(), nrm.size());
  ASSERT_EQ(pos.size() % 9, 0u);
  // Each vertex is on the surface of one collider: distance to its offset surface = -thickness.
  std::size_t on[3] = {0, 0, 0};
  for (std::size_t v = 0; v < pos.size() / 3; ++v) {
    const double x[3] = {pos[3 * v], pos[3 * v + 1], pos[3 * v + 2]};
    bool found = false;
    for (std::size_t c = 0; c < 3; ++c) {
      const auto ct = set.colliders()[c].query(x, t);
      if (std::abs(ct.distance + set.colliders()[c].thickness) < 1e-5) {
        ++on[c];
        found = true;
        break;
      }
    }
    ASSERT_TRUE(found) << "vertex " << v << " at " << x[0] << " " << x[1] << " " << x[2];
    const double n2 = double(nrm[3 * v]) * nrm[3 * v] + double(nrm[3 * v + 1]) * nrm[3 * v + 1] +
                      double(nrm[3 * v + 2]) * nrm[3 * v + 2];
    ASSERT_NEAR(n2, 1.0, 1e-5);
  }
  EXPECT_EQ(on[0], 48u * 24u * 6u);  // the sphere's tessellation
  EXPECT_EQ(on[1], 6u);              // the plane's square
  EXPECT_EQ(on[2], 80u * 3u);        // the icosphere's faces
}
