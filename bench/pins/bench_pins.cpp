// What moving pins cost (issue 13), and the virtual Kawabata tests as a user runs them.
//   build/bin/bench_pins --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
// BM_Step/<integrator>/<pins>: one step of a 64 x 64 mass-spring cloth clamped along its top
// edge (64 vertices) and one side (64), the clamps fixed, or the top one translating and the
// side one rotating (keyframes, smooth). The difference is the cost of placing the pins (and,
// for Baraff-Witkin, of the prescribed dv and the constraint forces); it should be negligible.
// BM_Kawabata/<test>: one run of scenes/kawabata/wool_<test>.yaml (28 or 14 frames of a
// 45-vertex swatch, Baraff-Witkin), without output; the three together are the time a user
// waits for `scripts/kawabata.py run scenes/kawabata/wool_*.yaml` minus process start-up.
#include <benchmark/benchmark.h>
#include <omp.h>

#include <map>
#include <memory>
#include <string>

#include "common/plugin_loader.hpp"
#include "loom/simulation.hpp"

namespace {

using loom_bench::loader;

const std::map<std::string, std::string> kIntegrators = {
    {"symplectic_euler", "{type: symplectic_euler, dt: 5.0e-5}"},
    {"harmonic_oscillation", "{type: harmonic_oscillation, dt: 4.0e-5}"},
    {"rk4", "{type: rk4, dt: 8.0e-5}"},
    {"baraff_witkin", "{type: baraff_witkin, dt: 2.0e-3}"}};

std::string scene(const std::string& integrator, bool moving) {
  std::string s = R"(
mesh: {grid: {nx: 64, ny: 64, width: 1.0, height: 1.0, plane: xy}}
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: {structural: 200, shear: 200, bend: 20}, density: 0.1}
solver: {type: eigen_pcg, eigen_pcg: {tolerance: 1.0e-5}}
threads: 1
integrator: )" + integrator + "\n";
  if (moving)
    s += "pins: [{name: top, group: top_edge, motion: {type: translate, velocity: [0.01, 0, 0]}},\n"
         "       {name: side, box: {min: [-0.01, 0.05, -1], max: [0.01, 0.95, 1]}, motion: {type: keyframes, "
         "axis: [0, 0, 1], interpolation: smooth, keys: [{t: 0}, {t: 10, angle: 0.5, translate: [0, 0.1, 0]}]}}]\n";
  else
    s += "pins: [{name: top, group: top_edge}, {name: side, box: {min: [-0.01, 0.05, -1], max: [0.01, 0.95, 1]}}]\n";
  return s;
}

void BM_Step(benchmark::State& st, const std::string& name, bool moving) {
  omp_set_num_threads(1);
  loom::Simulation::set_notes(false);
  auto sim = loom::Simulation::from_string(scene(kIntegrators.at(name), moving), "bench_pins.yaml", ".", {}, loader());
  for (int k = 0; k < 3; ++k) sim->step();
  for (auto _ : st) sim->step();
  st.counters["pinned"] = static_cast<double>(sim->scene().state.pin_list.size());
}

void BM_Kawabata(benchmark::State& st, const std::string& test) {
  loom::Simulation::set_notes(false);
  const std::string path = std::string(LOOM_SOURCE_DIR) + "/scenes/kawabata/wool_" + test + ".yaml";
  for (auto _ : st) {
    loom::Simulation sim(path, {"output=null"}, loader());
    for (int f = 0; f < sim.frames(); ++f) sim.advance_frame();
    benchmark::DoNotOptimize(sim.scene().state.x.data());
  }
}

}  // namespace

int main(int argc, char** argv) {
  for (const auto& [name, yaml] : kIntegrators) {
    for (const bool moving : {false, true})
      benchmark::RegisterBenchmark(("BM_Step/" + name + (moving ? "/moving" : "/fixed")).c_str(),
                                   [name, moving](benchmark::State& st) { BM_Step(st, name, moving); })
          ->Unit(benchmark::kMicrosecond);
  }
  for (const char* t : {"weft", "warp", "shear"})
    benchmark::RegisterBenchmark((std::string("BM_Kawabata/") + t).c_str(),
                                 [t](benchmark::State& st) { BM_Kawabata(st, t); })
        ->Unit(benchmark::kMillisecond);
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
