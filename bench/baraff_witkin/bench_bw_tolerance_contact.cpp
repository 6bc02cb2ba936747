// What the filtered PCG's tolerance costs in accuracy on contact scenes (issue 15; the wool hang
// without contact is bw_tolerance_error in bench_baraff_witkin). Counters only, no timings: they
// do not depend on the machine's load.
//
// bw_tolerance_contact/<scene>/<preconditioner>/tol<k>: the scene (contact_tolerance.hpp) run
// with filtered_pcg at tolerance 10^-k against the same scene at tolerance 1e-10 (sa_amg) at h
// and at h/2, sampled at the same time:
//   iters                  PCG iterations per step at 10^-k
//   rms_solve_err, max_solve_err   RMS / largest vertex distance to the 1e-10 run, over the cloth width
//   rms_time_err, max_time_err     the same between the 1e-10 runs at h and h/2
//   solve_over_time        rms_solve_err / rms_time_err (max_solve_over_time: the max ones)
//   energy_solve_err, energy_time_err   |E(10^-k) - E(1e-10)|, |E(h) - E(h/2)| (J, total energy at the end)
//   penetration_mm, ref_penetration_mm  deepest vertex inside the collider's true surface, any step
//   intersections, ref_intersections    most intersecting triangle pairs in a sampled step
//   rms_floor_err          RMS distance between the 1e-10 runs with sa_amg and block_jacobi: how far
//                          rounding-level differences carry over the run (contact and folding
//                          amplify them; where it is not far below rms_time_err, the end-of-run
//                          errors measure that divergence, not the tolerance)
//   loc_solve_err, loc_time_err   one-step errors along the 1e-10 trajectory (local_errors():
//                          each step restarted from the 1e-10 run's state), means over the steps
//   loc_solve_over_time    their ratio; loc_max_ratio: the largest per-step ratio
//
//   OMP_NUM_THREADS=1 build/bin/bench_bw_tolerance_contact --benchmark_counters_tabular=true
#include <benchmark/benchmark.h>

#include <cmath>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "contact_tolerance.hpp"

namespace {

namespace ts = loom::tolerance_study;

std::vector<ts::ContactScene> scenes() {
  return {
      ts::drape(32, "type: gnatv, material_file: " LOOM_SOURCE_DIR "/materials/wool.yaml", "drape_wool32", 150),
      ts::drape(64, "type: gnatv, material_file: " LOOM_SOURCE_DIR "/materials/wool.yaml", "drape_wool64", 100),
      ts::drape(32, "type: gnatv, fabric: 11oz-black-denim", "drape_denim32", 150),
      ts::moving_pins(32, 100),
      ts::fold(14, 250),
      ts::fold(32, 250),
      ts::spinning_ball_self(32, 150),
  };
}

// The 1e-10 runs of a scene (sa_amg at h and h/2, block_jacobi at h: two solutions of the same
// steps that differ only by rounding-level solve errors), computed once per scene.
struct References {
  ts::RunResult ref, half, other;
};
const References& references(const ts::ContactScene& sc) {
  static std::map<std::string, References> cache;
  auto it = cache.find(sc.name);
  if (it == cache.end()) {
    References r{ts::run(sc, 1e-10, "sa_amg", sc.dt, sc.steps), ts::run(sc, 1e-10, "sa_amg", 0.5 * sc.dt, 2 * sc.steps),
                 ts::run(sc, 1e-10, "block_jacobi", sc.dt, sc.steps)};
    it = cache.emplace(sc.name, std::move(r)).first;
  }
  return it->second;
}

void BM_ToleranceContact(benchmark::State& st, const ts::ContactScene& sc, const std::string& pc, int k) {
  ts::Study s;
  ts::LocalErrors loc;
  double floor = 0;
  for (auto _ : st) {
    const References& r = references(sc);
    const ts::RunResult run = ts::run(sc, std::pow(10.0, -k), pc, sc.dt, sc.steps);
    s = ts::compare(sc, r.ref, r.half, run);
    floor = ts::distance(r.other.x, r.ref.x, sc.width).rms;
    loc = ts::local_errors(sc, std::pow(10.0, -k), pc, sc.steps);
  }
  st.counters["loc_solve_err"] = loc.mean_solve;
  st.counters["loc_time_err"] = loc.mean_time;
  st.counters["loc_solve_over_time"] = loc.mean_solve / loc.mean_time;
  st.counters["loc_max_ratio"] = loc.max_ratio;
  st.counters["rms_floor_err"] = floor;
  st.counters["iters"] = s.run.iterations_per_step;
  st.counters["ref_iters"] = s.ref.iterations_per_step;
  st.counters["rms_solve_err"] = s.solve_err.rms;
  st.counters["max_solve_err"] = s.solve_err.max;
  st.counters["rms_time_err"] = s.time_err.rms;
  st.counters["max_time_err"] = s.time_err.max;
  st.counters["solve_over_time"] = s.solve_err.rms / s.time_err.rms;
  st.counters["max_solve_over_time"] = s.solve_err.max / s.time_err.max;
  st.counters["energy_solve_err"] = s.energy_solve_err;
  st.counters["energy_time_err"] = s.energy_time_err;
  st.counters["penetration_mm"] = 1e3 * s.run.max_penetration;
  st.counters["ref_penetration_mm"] = 1e3 * s.ref.max_penetration;
  st.counters["intersections"] = s.run.max_intersections;
  st.counters["ref_intersections"] = s.ref.max_intersections;
}

const bool registered = [] {
  for (const ts::ContactScene& sc : scenes())
    for (const char* pc : {"sa_amg", "block_jacobi"})
      for (int k : {2, 3, 4, 5})
        benchmark::RegisterBenchmark(
            ("bw_tolerance_contact/" + sc.name + "/" + pc + "/tol" + std::to_string(k)).c_str(),
            [sc, pc = std::string(pc), k](benchmark::State& st) { BM_ToleranceContact(st, sc, pc, k); })
            ->Iterations(1)
            ->Unit(benchmark::kSecond);
  return true;
}();

}  // namespace

BENCHMARK_MAIN();
