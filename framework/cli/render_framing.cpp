#include "render_framing.hpp"

#include <dlfcn.h>

#include <algorithm>
#include <cmath>

#include "loom/collider_geometry.hpp"

namespace fs = std::filesystem;

namespace loom::cli {

namespace {

// A symbol of the renderer module `type` (already loaded), or null.
void* module_symbol(const Registry& registry, const std::string& type, const char* name) {
  for (const auto& info : registry.list())
    if (info.kind == PluginKind::Renderer && info.name == type && !info.module_path.empty())
      if (void* h = ::dlopen(info.module_path.c_str(), RTLD_NOW | RTLD_NOLOAD)) {
        void* f = ::dlsym(h, name);
        ::dlclose(h);
        return f;
      }
  return nullptr;
}

}  // namespace

Framing frame_sequence(const std::vector<fs::path>& frames,
                       const std::function<void(const fs::path&, std::vector<double>&, double*)>& read,
                       const Params& root, const Params& render, const ColliderSet& colliders,
                       const Registry& registry, const std::string& type, Renderer* renderer) {
  Framing fr;
  std::string fit = "sequence";
  bool ground = true;
  if (render.valid()) {
    fit = render.get_choice("fit", fit, {"sequence", "first_frame"});
    ground = render.get("ground", ground);
  }
  // A plane collider is the scene's own ground.
  if (Params cp = root.child("colliders"); cp.valid() && cp.is_sequence())
    for (std::size_t k = 0; k < cp.size(); ++k)
      if (cp.at(k).is_map() && cp.at(k).has("type") && cp.at(k).child("type").as_string() == "plane") ground = false;
  // Up is against gravity (the scene's, default -y).
  double g[3] = {0, -9.81, 0};
  if (Params gp = root.child("gravity"); gp.valid()) {
    const auto v = gp.as_doubles();
    if (v.size() == 3) std::copy(v.begin(), v.end(), g);
  }
  const double gn = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
  if (gn > 0)
    for (int c = 0; c < 3; ++c) fr.up[c] = -g[c] / gn;

  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  double lowest = 1e300;  // along up, cloth and colliders
  std::vector<double> x;
  std::vector<std::pair<double, std::size_t>> times;
  const std::size_t count = fit == "sequence" || ground ? frames.size() : 1;
  for (std::size_t k = 0; k < count; ++k) {
    double t = 0;
    read(frames[k], x, &t);
    times.push_back({t, k});
    for (std::size_t i = 0; i + 2 < x.size(); i += 3) {
      for (int c = 0; c < 3; ++c) {
        lo[c] = std::min(lo[c], x[i + c]);
        hi[c] = std::max(hi[c], x[i + c]);
      }
      lowest = std::min(lowest, x[i] * fr.up[0] + x[i + 1] * fr.up[1] + x[i + 2] * fr.up[2]);
    }
  }
  for (int c = 0; c < 3; ++c) {
    fr.lo[c] = lo[c];
    fr.hi[c] = hi[c];
    fr.center[c] = 0.5 * (lo[c] + hi[c]);
  }
  const double diag = std::hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
  fr.plane_size = std::max(1e-3, 2.0 * diag);
  if (ground && !colliders.empty()) {
    // The colliders stand on the ground too (a ball under the cloth): their lowest point at
    // every frame's time.
    std::vector<float> pos, nrm;
    for (const auto& [t, k] : times) {
      pos.clear();
      nrm.clear();
      collider_triangles(colliders, t, fr.center, fr.plane_size, pos, nrm);
      for (std::size_t i = 0; i + 2 < pos.size(); i += 3)
        lowest = std::min(lowest, double(pos[i]) * fr.up[0] + double(pos[i + 1]) * fr.up[1] + double(pos[i + 2]) * fr.up[2]);
    }
  }
  if (fit == "sequence")
    if (auto f = reinterpret_cast<RendererFitCameraFn>(module_symbol(registry, type, kRendererFitCameraSymbol))) {
      const float flo[3] = {float(lo[0]), float(lo[1]), float(lo[2])}, fhi[3] = {float(hi[0]), float(hi[1]), float(hi[2])};
      f(renderer, flo, fhi);
    }
  if (ground)
    if (auto f = reinterpret_cast<RendererGroundFn>(module_symbol(registry, type, kRendererGroundSymbol))) {
      // Under the lowest point by 1% of the cloth's size, below the centre.
      const double h = std::max(diag, 1e-3);
      const double above = fr.center[0] * fr.up[0] + fr.center[1] * fr.up[1] + fr.center[2] * fr.up[2] - (lowest - 0.01 * h);
      for (int c = 0; c < 3; ++c) fr.ground_point[c] = fr.center[c] - above * fr.up[c];
      const float p[3] = {float(fr.ground_point[0]), float(fr.ground_point[1]), float(fr.ground_point[2])};
      const float n[3] = {float(fr.up[0]), float(fr.up[1]), float(fr.up[2])};
      f(renderer, p, n, float(4.0 * h));
      fr.ground = true;
    }
  return fr;
}

}  // namespace loom::cli
