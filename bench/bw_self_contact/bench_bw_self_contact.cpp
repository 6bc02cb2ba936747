// Baraff-Witkin with self-collision, with and without self-contacts in the implicit solve
// (integrator key implicit_self_contact; docs/CONTACT.md "Self-contact in the Baraff-Witkin
// step"): one step of the draped cloth (N x N mass-spring cloth, 1 m, on the spinning ball of
// scenes/draped_ball_*.yaml, as bench/self_collision) at N = 64 and 128, from the state after
// 0.35 s of draping (when folds start). Counters per step: the after-step response's impulses
// (proximity + CCD), its CCD impulses and frozen vertices, the linear solver's iterations (all
// solves of the step), and the response's seconds.
//   build/bin/bench_bw_self_contact --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>
#include <omp.h>

#include <map>
#include <memory>
#include <string>

#include "common/plugin_loader.hpp"
#include "loom/simulation.hpp"

namespace {

std::string scene(int n, bool implicit) {
  return "mesh: {grid: {nx: " + std::to_string(n) + ", ny: " + std::to_string(n) +
         ", width: 1.0, height: 1.0, plane: xz}}\n" + R"(
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: {structural: 200, shear: 200, bend: 20}, density: 0.1}
solver: {type: eigen_pcg, eigen_pcg: {tolerance: 1.0e-5}}
colliders: [{type: sphere, center: [0.5, -0.35, -0.5], radius: 0.3, thickness: 0.004, friction: 0.5,
             motion: {type: rotate, axis: [0, 1, 0], angular_velocity: 2.0}}]
integrator: {type: baraff_witkin, dt: 2.0e-3, implicit_self_contact: )" +
         (implicit ? "true" : "false") + "}\nself_collision: {thickness: " + std::to_string(0.25 / (n - 1)) +
         ", friction: 0.3}\n";
}

using loom_bench::loader;

const loom::State& draped(int n) {
  static std::map<int, std::unique_ptr<loom::Simulation>> sims;
  auto& sim = sims[n];
  if (!sim) {
    sim = loom::Simulation::from_string(scene(n, true), "bench.yaml", ".", {}, loader());
    for (int k = 0; k < 175; ++k) sim->step();
  }
  return sim->scene().state;
}

void BM_BwStep(benchmark::State& st, bool implicit) {
  const int n = static_cast<int>(st.range(0));
  omp_set_num_threads(static_cast<int>(st.range(1)));
  loom::Simulation::set_notes(false);
  // The count in the scene too: `threads: auto` would choose its own (and adapt it during the run).
  const std::string threads = "threads=" + std::to_string(st.range(1));
  auto sim = loom::Simulation::from_string(scene(n, implicit), "bench.yaml", ".", {threads}, loader());
  sim->scene().state = draped(n);
  omp_set_num_threads(static_cast<int>(st.range(1)));  // draped() may have built an auto scene
  for (int k = 0; k < 3; ++k) sim->step();  // warm-up: work arrays, candidate lists, contact pattern
  double impulses = 0, ccd = 0, frozen = 0, iterations = 0, response = 0;
  for (auto _ : st) {
    sim->step();
    const auto& s = sim->scene().self_collision->last_stats();
    impulses += s.proximity + s.ccd_collisions;
    ccd += s.ccd_collisions;
    frozen += s.frozen;
    response += s.response_seconds;
    iterations += sim->integrator().last_step().linear_iterations;
  }
  using C = benchmark::Counter;
  st.counters["vertices"] = static_cast<double>(n) * n;
  st.counters["impulses"] = C(impulses, C::kAvgIterations);
  st.counters["ccd"] = C(ccd, C::kAvgIterations);
  st.counters["frozen"] = C(frozen, C::kAvgIterations);
  st.counters["pcg_iterations"] = C(iterations, C::kAvgIterations);
  st.counters["response_ms"] = C(1e3 * response, C::kAvgIterations);
}

void args(benchmark::internal::Benchmark* b) {
  for (int n : {64, 128}) b->Args({n, 2});
  b->Unit(benchmark::kMillisecond);
}

}  // namespace

BENCHMARK_CAPTURE(BM_BwStep, after_step_response_only, false)->Apply(args);
BENCHMARK_CAPTURE(BM_BwStep, implicit_self_contact, true)->Apply(args);

BENCHMARK_MAIN();
