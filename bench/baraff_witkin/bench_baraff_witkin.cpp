// One Baraff-Witkin step (assembly + solve) of the hanging wool cloth (gnatv, 10 m x 10 m,
// top corners pinned, h = 0.01, Kang-Cho c_d = 0.01 as in scenes/wool_hanging_32.yaml) with
// eigen_pcg (block Jacobi, relative residual 1e-5) and eigen_ldlt, on 32x32, 128x128 and
// 256x256 grids. The cloth is first advanced `warmup` steps from rest so the measured steps
// see a deformed, moving cloth. Counters: assembly and solve ms per step (forces +
// Jacobians + system vs factorize + solve), iterations per step, last relative residual.
#include <benchmark/benchmark.h>

#include <memory>
#include <string>

#include "baraff_witkin.hpp"
#include "eigen_ldlt.hpp"
#include "eigen_pcg.hpp"
#include "gnatv_material.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "loom/scene.hpp"

namespace {

std::unique_ptr<loom::Scene> wool_scene(int n, bool ldlt) {
  auto sc = std::make_unique<loom::Scene>();
  sc->mesh = loom::make_grid(n, n, 10.0, 10.0, loom::GridPlane::XY);
  const loom::Params p = loom::Params::from_string(
      "material_file: " + std::string(LOOM_SOURCE_DIR) + "/materials/wool.yaml\n", "<bench>");
  sc->material = std::make_unique<loom::gnatv::GnatvMaterial>(p, sc->mesh);
  loom::State& s = sc->state;
  s.resize(sc->mesh.num_vertices());
  std::copy(sc->mesh.positions.begin(), sc->mesh.positions.end(), s.x.begin());
  sc->material->compute_masses(s.mass);
  s.pin((n - 1) * n);      // top-left
  s.pin(n * n - 1);        // top-right
  s.update_inverse_masses();
  sc->gravity = {0, -9.81, 0};
  if (ldlt) {
    sc->solver = std::make_unique<loom::EigenLdlt>();
  } else {
    loom::PcgOptions o;
    o.tolerance = 1e-5;
    sc->solver = std::make_unique<loom::EigenPcg>(o);
  }
  return sc;
}

void BM_BaraffWitkinStep(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  const bool ldlt = st.range(1) != 0;
  const int warmup = static_cast<int>(st.range(2));
  auto sc = wool_scene(n, ldlt);
  loom::BaraffWitkinOptions o;
  o.kang_cho_damping = 0.01;
  loom::BaraffWitkin bw(o);
  const double h = 0.01;
  bw.prepare(*sc, h);
  for (int k = 0; k < warmup; ++k) bw.step(*sc, h);
  double assemble = 0, solve = 0, residual = 0;
  long iterations = 0, steps = 0;
  for (auto _ : st) {
    bw.step(*sc, h);
    const loom::StepStats s = bw.last_step();
    assemble += s.assemble_seconds;
    solve += s.solve_seconds;
    iterations += s.linear_iterations;
    residual = s.linear_residual;
    ++steps;
  }
  st.counters["assemble_ms"] = 1e3 * assemble / steps;
  st.counters["solve_ms"] = 1e3 * solve / steps;
  st.counters["iters"] = static_cast<double>(iterations) / steps;
  st.counters["residual"] = residual;
  st.counters["vertices"] = n * n;
}

// The material's share of the assembly: forces + Jacobians (gnatv), same deformed state.
void BM_MaterialForcesJacobians(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  auto sc = wool_scene(n, false);
  loom::BaraffWitkinOptions o;
  o.kang_cho_damping = 0.01;
  loom::BaraffWitkin bw(o);
  bw.prepare(*sc, 0.01);
  for (int k = 0; k < 10; ++k) bw.step(*sc, 0.01);
  loom::BsrMatrix dfdx(&bw.pattern()), dfdv(&bw.pattern());
  std::vector<double> f(sc->state.x.size());
  for (auto _ : st) {
    sc->material->compute_forces(sc->state.x, sc->state.v, f);
    sc->material->compute_jacobians(sc->state.x, sc->state.v, dfdx, &dfdv);
    benchmark::DoNotOptimize(dfdx.values().data());
  }
}

}  // namespace

BENCHMARK(BM_MaterialForcesJacobians)->Name("gnatv_forces_jacobians/wool32")->Arg(32)->Unit(benchmark::kMillisecond);

// args: grid n, solver (0 = eigen_pcg, 1 = eigen_ldlt), warm-up steps
BENCHMARK(BM_BaraffWitkinStep)->Name("bw_step/wool32/eigen_pcg")->Args({32, 0, 20})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BaraffWitkinStep)->Name("bw_step/wool32/eigen_ldlt")->Args({32, 1, 20})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BaraffWitkinStep)->Name("bw_step/wool128/eigen_pcg")->Args({128, 0, 10})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BaraffWitkinStep)->Name("bw_step/wool128/eigen_ldlt")->Args({128, 1, 10})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BaraffWitkinStep)->Name("bw_step/wool256/eigen_pcg")->Args({256, 0, 3})->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_BaraffWitkinStep)->Name("bw_step/wool256/eigen_ldlt")->Args({256, 1, 2})->Unit(benchmark::kMillisecond)->Iterations(1);

BENCHMARK_MAIN();
