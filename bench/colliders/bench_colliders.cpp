// What contact costs: one step of the draped-ball scene (128 x 128 cloth resting on a spinning
// ball, Kang & Cho Fig. 9) with and without the collider, for each integrator.
//   build/bin/bench_colliders --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
// The cloth is first draped (stepped with the collider until it rests on the ball), so the
// "with" runs have a few thousand contacts per step; the "without" runs take the same state.
#include <benchmark/benchmark.h>
#include <omp.h>

#include <map>
#include <memory>

#include "common/plugin_loader.hpp"
#include "loom/simulation.hpp"

namespace {

std::string scene(const std::string& integrator, bool collider) {
  std::string s = R"(
mesh: {grid: {nx: 128, ny: 128, width: 1.0, height: 1.0, plane: xz}}
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: {structural: 200, shear: 200, bend: 20}, density: 0.1}
integrator: )" + integrator + R"(
solver: {type: eigen_pcg, eigen_pcg: {tolerance: 1.0e-5}}
)";
  if (collider)
    s += "colliders: [{type: sphere, center: [0.5, -0.35, -0.5], radius: 0.3, thickness: 0.004, friction: 0.5,"
         " motion: {type: rotate, axis: [0, 1, 0], angular_velocity: 2.0}}]\n";
  return s;
}

const std::map<std::string, std::string> kIntegrators = {
    {"symplectic_euler", "{type: symplectic_euler, dt: 5.0e-5}"},
    {"harmonic_oscillation", "{type: harmonic_oscillation, dt: 4.0e-5}"},
    {"rk4", "{type: rk4, dt: 8.0e-5}"},
    {"baraff_witkin", "{type: baraff_witkin, dt: 2.0e-3}"}};

using loom_bench::loader;

// The draped state, computed once with BW (cheap, large steps) and shared by all runs.
const loom::State& draped() {
  static std::unique_ptr<loom::Simulation> sim = [] {
    auto s = loom::Simulation::from_string(scene(kIntegrators.at("baraff_witkin"), true), "bench.yaml", ".", {}, loader());
    for (int k = 0; k < 150; ++k) s->step();  // 0.3 s: the cloth has landed and wraps the ball
    return s;
  }();
  return sim->scene().state;
}

void BM_Step(benchmark::State& st, const std::string& name, bool collider) {
  omp_set_num_threads(static_cast<int>(st.range(0)));
  loom::Simulation::set_notes(false);
  // The count in the scene too: `threads: auto` would choose its own (and adapt it during the run).
  const std::string threads = "threads=" + std::to_string(st.range(0));
  auto sim = loom::Simulation::from_string(scene(kIntegrators.at(name), collider), "bench.yaml", ".", {threads}, loader());
  sim->scene().state = draped();
  omp_set_num_threads(static_cast<int>(st.range(0)));  // draped() may have built an auto scene
  for (int k = 0; k < 3; ++k) sim->step();
  int contacts = 0;
  for (auto _ : st) {
    sim->step();
    if (!collider) continue;
  }
  if (collider) {
    const auto& x = sim->scene().state.x;
    for (std::size_t i = 0; i < x.size(); i += 3) {
      const double dx = x[i] - 0.5, dy = x[i + 1] + 0.35, dz = x[i + 2] + 0.5;
      contacts += (dx * dx + dy * dy + dz * dz) < (0.31 * 0.31);
    }
  }
  st.counters["contacts"] = contacts;
  st.counters["vertices"] = 128 * 128;
}

void register_all() {
  for (const auto& [name, _] : kIntegrators)
    for (bool c : {false, true})
      benchmark::RegisterBenchmark(("DrapedBall/" + name + (c ? "/with_collider" : "/without_collider")).c_str(),
                                   [name = name, c](benchmark::State& st) { BM_Step(st, name, c); })
          ->Arg(1)
          ->Arg(2)
          ->Unit(benchmark::kMillisecond)
          ->UseRealTime();
}

}  // namespace

int main(int argc, char** argv) {
  register_all();
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
