// Time per 1280x720 frame of a 128x128 cloth on the gl renderer (llvmpipe without a GPU):
// MDF rotation vs plain normal mapping vs flat shading, supersample 1 and 2.
// Each iteration: positions -> normals/tangents, upload, draw, glReadPixels, downsample (no PNG).
#include <benchmark/benchmark.h>

#include <ctime>
#include <memory>

#include "cloth_shapes.hpp"
#include "gl_renderer.hpp"

using namespace loom;
using namespace loom::render;

static void BM_RenderFrame(benchmark::State& state) {
  const float modes[] = {shading::LOOM_MODE_FLAT, shading::LOOM_MODE_NORMAL_MAP, shading::LOOM_MODE_ROTATE_EXACT,
                         shading::LOOM_MODE_ROTATE_PAPER};
  const Mesh cloth = folded_cloth(128, 1.0, 2.5, 0.08);
  RenderSettings s;
  s.width = 1280;
  s.height = 720;
  s.supersample = int(state.range(1));
  s.fabric.mode = modes[state.range(0)];
  s.fabric.mdf = state.range(2) ? shading::LOOM_MDF_ASHIKHMIN : shading::LOOM_MDF_WARD;
  if (state.range(3)) {  // close-up: the cloth covers the whole image (every pixel shaded)
    s.camera.has_position = s.camera.has_target = true;
    s.camera.position = glm::vec3(0.5f, 0.5f, 0.55f);
    s.camera.target = glm::vec3(0.5f, 0.5f, 0.0f);
  }
  GlRenderer r(s);
  try {
    r.begin(cloth);
  } catch (const std::exception& e) {
    state.SkipWithError(e.what());
    return;
  }
  std::vector<double> x = cloth.positions;
  // CPU time of the whole process (llvmpipe's worker threads included): less sensitive than
  // wall time to other jobs on a shared machine.
  auto process_cpu = [] {
    timespec t{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
  };
  const double c0 = process_cpu();
  for (auto _ : state) {
    x[2] += 1e-9;  // a "new frame"
    const auto& img = r.render_image(x);
    benchmark::DoNotOptimize(img.data());
  }
  state.counters["proc_cpu_ms"] = 1e3 * (process_cpu() - c0) / double(state.iterations());
  state.SetLabel(r.gl_renderer());
}
// Args: mode (0 flat, 1 normal mapping, 2 MDF rotation exact, 3 MDF rotation eq. 17), supersample,
// mdf (0 Ward, 1 AS), framing (0 the default camera, 1 close-up: every pixel is cloth).
BENCHMARK(BM_RenderFrame)
    ->ArgNames({"mode", "ss", "ashikhmin", "closeup"})
    ->Args({0, 1, 0, 0})->Args({1, 1, 0, 0})->Args({2, 1, 0, 0})->Args({3, 1, 0, 0})
    ->Args({1, 1, 1, 0})->Args({2, 1, 1, 0})
    ->Args({1, 2, 0, 0})->Args({2, 2, 0, 0})
    ->Args({0, 1, 0, 1})->Args({1, 1, 0, 1})->Args({2, 1, 0, 1})->Args({3, 1, 0, 1})
    ->Unit(benchmark::kMillisecond)->MinTime(1.0)->UseRealTime();

// The CPU part alone: vertex normals and tangents of the 128x128 cloth.
static void BM_VertexFrames(benchmark::State& state) {
  const Mesh cloth = folded_cloth(128, 1.0, 2.5, 0.08);
  std::vector<float> x(cloth.positions.begin(), cloth.positions.end());
  const auto uv = texture_coords(cloth);
  std::vector<float> n(x.size()), t(x.size());
  for (auto _ : state) {
    vertex_frames(x, uv, cloth.triangles, n, t);
    benchmark::DoNotOptimize(n.data());
  }
}
BENCHMARK(BM_VertexFrames)->Unit(benchmark::kMicrosecond);

BENCHMARK_MAIN();
