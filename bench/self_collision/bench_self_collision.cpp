// What self-collision costs: one step of the draped cloth (N x N mass-spring cloth, 1 m, on the
// spinning ball of scenes/draped_ball_*.yaml) with and without self_collision, for
// symplectic_euler and baraff_witkin at N = 64, 128, 256. The counters split the self-collision
// time per step into broad phase (refit + traversal, only on steps whose motion leaves the
// boxes of the last traversal; `rebuilds` is that fraction), narrow phase (proximity distances)
// and response (repulsion, CCD passes, fail-safe).
//   build/bin/bench_self_collision --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
// Thickness: a quarter of the edge length, 0.25 / (N - 1) m. The cloth is first draped with
// baraff_witkin and self-collision (0.35 s: it has landed and folds start; at 0.2 s a smoke run
// at 64^2 saw no contact yet); every run starts from that state. `impulses` counts the contact
// impulses per step, to show that contacts were active. The slope of cost against vertex count is read from the N = 64..256 rows.
#include <benchmark/benchmark.h>
#include <omp.h>

#include <map>
#include <memory>
#include <string>

#include "loom/simulation.hpp"

namespace {

std::string scene(int n, const std::string& integrator, bool self) {
  std::string s = "mesh: {grid: {nx: " + std::to_string(n) + ", ny: " + std::to_string(n) +
                  ", width: 1.0, height: 1.0, plane: xz}}\n" + R"(
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: {structural: 200, shear: 200, bend: 20}, density: 0.1}
solver: {type: eigen_pcg, eigen_pcg: {tolerance: 1.0e-5}}
colliders: [{type: sphere, center: [0.5, -0.35, -0.5], radius: 0.3, thickness: 0.004, friction: 0.5,
             motion: {type: rotate, axis: [0, 1, 0], angular_velocity: 2.0}}]
)";
  // symplectic_euler: dt = 5e-5 is stable at 128 (scenes/draped_ball_symplectic_euler.yaml); it scales with the edge.
  const double dt_se = 5.0e-5 * 127.0 / (n - 1);
  s += integrator == "symplectic_euler" ? "integrator: {type: symplectic_euler, dt: " + std::to_string(dt_se) + "}\n"
                                        : "integrator: {type: baraff_witkin, dt: 2.0e-3}\n";
  if (self) s += "self_collision: {thickness: " + std::to_string(0.25 / (n - 1)) + ", friction: 0.3}\n";
  return s;
}

loom::Registry& registry() {
  static loom::Registry r;
  return r;
}
loom::PluginLoader& loader() {
  static loom::PluginLoader l(registry());
  return l;
}

const loom::State& draped(int n) {
  static std::map<int, std::unique_ptr<loom::Simulation>> sims;
  auto& sim = sims[n];
  if (!sim) {
    sim = loom::Simulation::from_string(scene(n, "baraff_witkin", true), "bench.yaml", ".", {}, loader());
    for (int k = 0; k < 175; ++k) sim->step();
  }
  return sim->scene().state;
}

void BM_Step(benchmark::State& st, const std::string& integrator, bool self) {
  const int n = static_cast<int>(st.range(0));
  omp_set_num_threads(static_cast<int>(st.range(1)));
  loom::Simulation::set_notes(false);
  auto sim = loom::Simulation::from_string(scene(n, integrator, self), "bench.yaml", ".", {}, loader());
  sim->scene().state = draped(n);
  for (int k = 0; k < 3; ++k) sim->step();  // warm-up: work arrays and candidate lists sized
  double broad = 0, narrow = 0, response = 0, rebuilds = 0, candidates = 0, impulses = 0;
  for (auto _ : st) {
    sim->step();
    if (const auto* sc = sim->scene().self_collision.get()) {
      const auto& s = sc->last_stats();
      broad += s.broad_seconds;
      narrow += s.narrow_seconds;
      response += s.response_seconds;
      rebuilds += s.rebuilt ? 1 : 0;
      candidates += s.candidates_vt + s.candidates_ee;
      impulses += s.proximity + s.ccd_collisions;
    }
  }
  using C = benchmark::Counter;
  st.counters["vertices"] = static_cast<double>(n) * n;
  if (self) {
    st.counters["broad_ms"] = C(1e3 * broad, C::kAvgIterations);
    st.counters["narrow_ms"] = C(1e3 * narrow, C::kAvgIterations);
    st.counters["response_ms"] = C(1e3 * response, C::kAvgIterations);
    st.counters["rebuilds"] = C(rebuilds, C::kAvgIterations);
    st.counters["candidates"] = C(candidates, C::kAvgIterations);
    st.counters["impulses"] = C(impulses, C::kAvgIterations);
  }
}

void args(benchmark::internal::Benchmark* b) {
  for (int n : {64, 128, 256}) b->Args({n, 2});
  b->Unit(benchmark::kMillisecond);
}

BENCHMARK_CAPTURE(BM_Step, symplectic_euler_without, std::string("symplectic_euler"), false)->Apply(args);
BENCHMARK_CAPTURE(BM_Step, symplectic_euler_self_collision, std::string("symplectic_euler"), true)->Apply(args);
BENCHMARK_CAPTURE(BM_Step, baraff_witkin_without, std::string("baraff_witkin"), false)->Apply(args);
BENCHMARK_CAPTURE(BM_Step, baraff_witkin_self_collision, std::string("baraff_witkin"), true)->Apply(args);

}  // namespace

BENCHMARK_MAIN();
