// HO step (kang_cho_table1 stencil, Table 1 grid sizes) on the CPU plugin and on the CUDA
// backend's device glue run by the Thrust-OpenMP stand-in, with the state copied back every
// step (host_sync_every 1) or only every 1000th (the copy's cost is the difference).
#include <benchmark/benchmark.h>

#include <memory>
#include <string>

#include "common/table1.hpp"
#include "cuda_integrators.hpp"
#include "ho_integrator.hpp"
#include "loom/mesh.hpp"
#include "loom/scene.hpp"
#include "mass_spring.hpp"

using namespace loom;

namespace {

std::unique_ptr<Scene> make_scene(Index n) {
  auto sc = std::make_unique<Scene>();
  loom_bench::table1_cloth(*sc, static_cast<int>(n), "");
  return sc;
}

void report(benchmark::State& state, const Scene& sc) {
  const double S = static_cast<double>(sc.material->springs()->size());
  state.counters["springs"] = S;
  state.counters["springs_per_s"] = benchmark::Counter(S, benchmark::Counter::kIsIterationInvariantRate);
}

void BM_HoCpu(benchmark::State& state) {
  auto sc = make_scene(static_cast<Index>(state.range(0)));
  HoIntegrator integ(HoVariant::Velocity);
  integ.prepare(*sc, 1e-5);
  for (auto _ : state) integ.step(*sc, 1e-5);
  report(state, *sc);
}

void BM_HoDeviceOmp(benchmark::State& state) {
  auto sc = make_scene(static_cast<Index>(state.range(0)));
  const int sync = static_cast<int>(state.range(1));
  auto integ = loom::cuda::make_cuda_ho(loom::cuda::HoVariantD::Velocity, loom::cuda::Precision::Double, sync);
  integ->prepare(*sc, 1e-5);
  for (auto _ : state) integ->step(*sc, 1e-5);
  report(state, *sc);
}

}  // namespace

BENCHMARK(BM_HoCpu)->Arg(160)->Arg(336)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_HoDeviceOmp)
    ->Args({160, 1})
    ->Args({160, 1000})
    ->Args({336, 1})
    ->Args({336, 1000})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK_MAIN();
