// Draws the figures of docs/RENDERING.md with the gl renderer:
//   render_figures OUT_DIR
// fig10_weaves.png   (Kang & Cho Fig. 10) plain (1,1,1) | 2/1 twill (2,1,1) | 4/1 twill (4,1,1) | silk-like (0,100,1)
// fig11_twist.png    (Fig. 11) fibre twist N = 0 | 1 | 3
// fig6_mdf_rotation.png (Fig. 6) top: normal mapping, Ward | Ashikhmin; bottom: MDF rotation, Ward | Ashikhmin
#include <cstdio>
#include <string>
#include <vector>

#include "cloth_shapes.hpp"
#include "gl_renderer.hpp"

using namespace loom;
using namespace loom::render;

namespace {

constexpr int kTileW = 200, kTileH = 150;

struct Canvas {
  int w, h;
  std::vector<unsigned char> rgb;
  Canvas(int cols, int rows) : w(cols * kTileW), h(rows * kTileH), rgb(std::size_t(w) * h * 3, 255) {}
  // Tiles are stored with 6 bits per channel (the PNGs compress ~2x better; docs stay small).
  void put(int col, int row, const std::vector<unsigned char>& tile) {
    for (int y = 0; y < kTileH; ++y)
      for (int x = 0; x < kTileW; ++x)
        for (int k = 0; k < 3; ++k)
          rgb[(std::size_t(row * kTileH + y) * w + col * kTileW + x) * 3 + k] =
              static_cast<unsigned char>(tile[(std::size_t(y) * kTileW + x) * 3 + k] & 0xFC);
  }
};

shading::Fabric base_fabric() {
  shading::Fabric f = default_fabric();
  f.density_u = f.density_v = 28.0f;
  f.yarn_curvature = 0.6f;
  f.fibre_curvature = 0.3f;
  f.twists = 1.0f;
  f.alpha_along = 0.15f;
  f.alpha_across = 0.5f;
  f.weft_color = glm::vec3(0.42f, 0.10f, 0.08f);
  f.warp_color = glm::vec3(0.36f, 0.08f, 0.07f);
  f.specular = glm::vec3(0.12f);
  return f;
}

std::vector<unsigned char> draw(const shading::Fabric& f, const Mesh& cloth) {
  RenderSettings s;
  s.width = kTileW;
  s.height = kTileH;
  s.supersample = 3;
  s.fabric = f;
  s.camera.has_position = s.camera.has_target = true;
  s.camera.position = glm::vec3(0.72f, 0.78f, 1.55f);
  s.camera.target = glm::vec3(0.5f, 0.5f, 0.0f);
  s.camera.fov_deg = 38.0f;
  s.light.has_direction = true;
  s.light.direction = glm::normalize(glm::vec3(-0.35f, 0.45f, 1.0f));
  GlRenderer r(s);
  r.begin(cloth);
  return r.render_image(cloth.positions);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: render_figures OUT_DIR\n");
    return 2;
  }
  const std::string out = argv[1];
  const Mesh cloth = folded_cloth(96, 1.0, 1.5, 0.07);
  try {
    {
      Canvas c(4, 1);
      const float weaves[4][3] = {{1, 1, 1}, {2, 1, 1}, {4, 1, 1}, {0, 100, 1}};
      for (int k = 0; k < 4; ++k) {
        shading::Fabric f = base_fabric();
        f.n_w = weaves[k][0];
        f.n_pi = weaves[k][1];
        f.n_sigma = weaves[k][2];
        c.put(k, 0, draw(f, cloth));
      }
      write_png(out + "/fig10_weaves.png", c.w, c.h, c.rgb.data());
    }
    {
      Canvas c(3, 1);
      const float twists[3] = {0, 1, 3};
      for (int k = 0; k < 3; ++k) {
        shading::Fabric f = base_fabric();
        f.fibre_curvature = 0.4f;
        f.twists = twists[k];
        c.put(k, 0, draw(f, cloth));
      }
      write_png(out + "/fig11_twist.png", c.w, c.h, c.rgb.data());
    }
    {
      Canvas c(2, 2);
      for (int row = 0; row < 2; ++row)
        for (int col = 0; col < 2; ++col) {
          shading::Fabric f = base_fabric();
          f.density_u = f.density_v = 9.0f;
          f.yarn_curvature = 0.8f;
          f.twists = 0.0f;
          f.alpha_along = 0.12f;
          f.alpha_across = 0.45f;
          f.specular = glm::vec3(0.25f);
          f.mdf = col == 0 ? shading::LOOM_MDF_WARD : shading::LOOM_MDF_ASHIKHMIN;
          f.mode = row == 0 ? shading::LOOM_MODE_NORMAL_MAP : shading::LOOM_MODE_ROTATE_EXACT;
          c.put(col, row, draw(f, cloth));
        }
      write_png(out + "/fig6_mdf_rotation.png", c.w, c.h, c.rgb.data());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "render_figures: %s\n", e.what());
    return 1;
  }
  return 0;
}
