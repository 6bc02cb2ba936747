// One mass_spring + symplectic_euler step on the Kang & Cho Table 1 grids (double).
//
//   bench_mass_spring --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
//
// Arguments: {n, threads, stencil} with stencil 0 = kang_cho_table1, 1 = radius_sqrt5.
// Counters: springs (per step), springs_per_s, bytes_per_step (compulsory traffic model, see
// below) and bw (= bytes_per_step / time, bytes per second).
// Traffic model (double, N vertices, S springs, springs stored in traversal order):
//   forces: read x (24N), write f (24N), read i, j, k, l0 (24S);
//   integrator: read f, v, x, w (80N), write v, x (48N)      => 176 N + 24 S bytes.
#include <benchmark/benchmark.h>

#include <array>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <utility>

#include <omp.h>

#include "loom/bsr.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "loom/scene.hpp"
#include "mass_spring.hpp"
#include "symplectic_euler.hpp"

using namespace loom;

namespace {

const char* kStencils[] = {"kang_cho_table1", "radius_sqrt5"};

struct Fixture {
  std::unique_ptr<Scene> scene;
  std::unique_ptr<symplectic_euler::SymplecticEuler> se;
  std::vector<double> x0, v0;
};

// Built once per (n, stencil): the 336^2 setup takes a while.
Fixture& fixture(int n, int stencil) {
  static std::map<std::pair<int, int>, Fixture> cache;
  auto it = cache.find({n, stencil});
  if (it != cache.end()) return it->second;
  Fixture f;
  f.scene = std::make_unique<Scene>();
  Scene& sc = *f.scene;
  sc.mesh = make_grid(n, n, 1.0, 1.0, GridPlane::XY);
  Params p = Params::from_string(std::string("stencil: ") + kStencils[stencil] + "\nstiffness: 2000\ndensity: 0.1");
  sc.material = std::make_unique<mass_spring::MassSpringMaterial>(p, sc.mesh);
  State& st = sc.state;
  st.resize(sc.mesh.num_vertices());
  st.x = sc.mesh.positions;
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-1e-4, 1e-4);
  for (double& c : st.x) c += u(rng);
  sc.material->compute_masses(st.mass);
  st.update_inverse_masses();
  st.pin(sc.mesh.grid->index(0, n - 1));
  st.pin(sc.mesh.grid->index(n - 1, n - 1));
  f.se = std::make_unique<symplectic_euler::SymplecticEuler>(Params::from_string("{}"));
  f.x0 = st.x;
  f.v0 = st.v;
  return cache.emplace(std::make_pair(n, stencil), std::move(f)).first->second;
}

void BM_Step(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const int threads = static_cast<int>(state.range(1));
  const int stencil = static_cast<int>(state.range(2));
  Fixture& f = fixture(n, stencil);
  Scene& sc = *f.scene;
  sc.state.x = f.x0;
  sc.state.v = f.v0;
  omp_set_num_threads(threads);
  const double h = 1e-7;  // tiny: the state stays near rest however many steps run
  f.se->prepare(sc, h);
  for (auto _ : state) {
    f.se->step(sc, h);
    benchmark::ClobberMemory();
  }
  const double N = sc.state.size();
  const double S = sc.material->springs()->size();
  const double bytes = 176.0 * N + 24.0 * S;
  state.counters["springs"] = S;
  state.counters["springs_per_s"] = benchmark::Counter(S, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["bytes_per_step"] = bytes;
  state.counters["bw"] = benchmark::Counter(bytes, benchmark::Counter::kIsIterationInvariantRate);
  state.SetLabel(std::string(kStencils[stencil]) + " " + std::to_string(threads) + "T");
}

void BM_Forces(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const int threads = static_cast<int>(state.range(1));
  const int stencil = static_cast<int>(state.range(2));
  Fixture& f = fixture(n, stencil);
  Scene& sc = *f.scene;
  omp_set_num_threads(threads);
  std::vector<double> force(sc.state.x.size());
  for (auto _ : state) {
    sc.material->compute_forces(f.x0, f.v0, force);
    benchmark::ClobberMemory();
  }
  const double N = sc.state.size();
  const double S = sc.material->springs()->size();
  const double bytes = 48.0 * N + 24.0 * S;
  state.counters["springs_per_s"] = benchmark::Counter(S, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["bw"] = benchmark::Counter(bytes, benchmark::Counter::kIsIterationInvariantRate);
  state.SetLabel(std::string(kStencils[stencil]) + " " + std::to_string(threads) + "T");
}

// compute_jacobians (df/dx and df/dv blocks of every spring into the BSR pattern), for the
// implicit integrators.
void BM_Jacobian(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const int threads = static_cast<int>(state.range(1));
  Fixture& f = fixture(n, 0);
  Material& m = *f.scene->material;
  static std::map<int, std::unique_ptr<BsrPattern>> patterns;
  auto& pat = patterns[n];
  if (!pat) {
    std::vector<std::array<Index, 2>> pairs;
    m.jacobian_pairs(pairs);
    pat = std::make_unique<BsrPattern>(BsrPattern::from_pairs(f.scene->state.size(), pairs));
  }
  m.bind_pattern(*pat);
  BsrMatrix dfdx(pat.get());
  omp_set_num_threads(threads);
  for (auto _ : state) {
    m.compute_jacobians(f.x0, f.v0, dfdx, nullptr);
    benchmark::ClobberMemory();
  }
  const double S = m.springs()->size();
  state.counters["springs_per_s"] = benchmark::Counter(S, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["blocks"] = pat->nnz_blocks();
  state.SetLabel(std::string(kStencils[0]) + " " + std::to_string(threads) + "T");
}

void StepArgs(benchmark::internal::Benchmark* b) {
  for (int n : {160, 176, 200, 256, 296, 336})
    for (int t : {1, 2}) b->Args({n, t, 0});
  for (int t : {1, 2}) b->Args({336, t, 1});
}

}  // namespace

BENCHMARK(BM_Step)->Apply(StepArgs)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Forces)->Args({336, 1, 0})->Args({336, 2, 0})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Jacobian)->Args({256, 1})->Args({256, 2})->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
