// What a mesh collider costs against the analytic sphere it stands for: one contact pass
// (ColliderSet::resolve_contacts, what the explicit integrators run after every step, and the
// same queries Baraff-Witkin makes twice per step) over a 128 x 128 cloth's vertices lying
// just outside a ball of radius 0.3, for the analytic sphere and for icospheres of 80 and
// 1280 faces (scenes/meshes), static and spinning.
//   build/bin/bench_mesh_collider --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
// The last rows put the vertices far from the body (ColliderSet's pass needs only distances
// below zero, so a mesh answers them from bounds).
// Report: time per pass and per vertex query (time / vertices), mesh / sphere ratio (the BVH makes a query
// O(log faces): compare 80 and 1280 faces).
#include <benchmark/benchmark.h>
#include <omp.h>

#include <cmath>
#include <random>
#include <string>

#include "loom/collider.hpp"
#include "loom/params.hpp"

namespace {

loom::ColliderSet colliders(const std::string& kind, bool spinning) {
  const std::string motion = spinning ? ", motion: {type: rotate, axis: [0, 1, 0], angular_velocity: 2.0}" : "";
  std::string c;
  if (kind == "sphere")
    c = "{type: sphere, center: [0.5, -0.35, -0.5], radius: 0.3, thickness: 0.004, friction: 0.5" + motion + "}";
  else
    c = "{type: mesh, obj: " + kind + ", scale: 0.3, offset: [0.5, -0.35, -0.5], thickness: 0.004, friction: 0.5" +
        motion + "}";
  return loom::ColliderSet::parse(loom::Params::from_string("colliders: [" + c + "]", "bench.yaml").child("colliders"),
                                  LOOM_SOURCE_DIR "/scenes/meshes");
}

// 128 x 128 vertices on the upper half of a shell 0 - 2 mm outside the offset surface, half
// of them pushed 1 mm inside it (contacts to resolve), at rest.
// far = true: the cloth of scenes/draped_ball_*.yaml as released, a flat 1 m sheet 5 cm above
// the ball (no contacts: every query is a far vertex, answered from the hierarchy's bounds).
loom::State cloth_state(bool far) {
  loom::State s;
  const loom::Index n = 128 * 128;
  s.resize(n);
  if (far) {
    for (loom::Index i = 0; i < n; ++i) {
      s.mass[i] = 1e-5;
      s.x[3 * i] = (i % 128) / 127.0;
      s.x[3 * i + 1] = 0.0;
      s.x[3 * i + 2] = -(i / 128) / 127.0;
    }
    s.update_inverse_masses();
    return s;
  }
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> U(0, 1);
  for (loom::Index i = 0; i < n; ++i) {
    s.mass[i] = 1e-5;
    const double th = std::acos(U(rng)), ph = 2 * M_PI * U(rng);
    const double r = 0.304 + (i % 2 ? 0.002 * U(rng) : -0.001);
    s.x[3 * i] = 0.5 + r * std::sin(th) * std::cos(ph);
    s.x[3 * i + 1] = -0.35 + r * std::cos(th);
    s.x[3 * i + 2] = -0.5 + r * std::sin(th) * std::sin(ph);
  }
  s.update_inverse_masses();
  return s;
}

void BM_ContactPass(benchmark::State& st, const std::string& kind, bool spinning, bool far) {
  omp_set_num_threads(static_cast<int>(st.range(0)));
  const loom::ColliderSet set = colliders(kind, spinning);
  const loom::State start = cloth_state(far);
  loom::State s = start;
  int contacts = 0;
  for (auto _ : st) {
    st.PauseTiming();
    s.x = start.x;
    std::fill(s.v.begin(), s.v.end(), 0.0);
    st.ResumeTiming();
    contacts = set.resolve_contacts(s, 0.1, 1e-3);
    benchmark::DoNotOptimize(s.x.data());
  }
  st.counters["contacts"] = contacts;
  st.counters["vertices"] = static_cast<double>(start.size());  // time / vertices = cost of one query
}

}  // namespace

BENCHMARK_CAPTURE(BM_ContactPass, sphere_static, std::string("sphere"), false, false)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_ContactPass, sphere_spinning, std::string("sphere"), true, false)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_ContactPass, mesh80_static, std::string("icosphere1.obj"), false, false)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_ContactPass, mesh1280_static, std::string("icosphere3.obj"), false, false)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_ContactPass, mesh1280_spinning, std::string("icosphere3.obj"), true, false)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
// Far vertices (the sheet 5 cm above the ball): the early-out of the cutoff query.
BENCHMARK_CAPTURE(BM_ContactPass, sphere_far, std::string("sphere"), false, true)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_ContactPass, mesh1280_far, std::string("icosphere3.obj"), false, true)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_ContactPass, mesh1280_spinning_far, std::string("icosphere3.obj"), true, true)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);

BENCHMARK_MAIN();
