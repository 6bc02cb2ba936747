// What self-collision costs: one step of the draped cloth (N x N mass-spring cloth, 1 m, on the
// spinning ball of scenes/draped_ball_*.yaml) with and without self_collision, for
// symplectic_euler and baraff_witkin at N = 64, 128, 256 (baraff_witkin with filtered_pcg's
// block Jacobi in the rows baraff_witkin_{without,self_collision}, and with its sa_amg in the
// rows baraff_witkin_sa_amg_{without,self_collision}). The counters split the self-collision
// time per step into broad phase (the per-vertex reach check every step; refreshes of the pairs
// of the few vertices that left their reach, or full rebuilds: refit + parallel traversal;
// `rebuilds` is the fraction of steps whose lists changed either way, `full_rebuilds` per step,
// `refreshed` vertices per step), narrow phase (proximity distances) and response (repulsion,
// CCD passes, fail-safe; it includes refreshes that responses cause); for baraff_witkin also the
// search inside its step for its self-contact springs (`search_broad_ms`: renewing the lists,
// `search_narrow_ms`: the pairs' filter and distances; SelfCollisionTotals::search_*), which
// until 2026-12-02 no counter showed (it was only in the difference of the two steps).
// Run (one line), then read the table, the phases and the log-log slope of cost against vertices:
//   export LOOM_BENCH_DRAPE_CACHE=/tmp/loom_drape
//   build/bin/bench_self_collision --benchmark_filter=BM_Step/symplectic_euler --benchmark_repetitions=3
//       --benchmark_report_aggregates_only=true --benchmark_out=sc_se.json --benchmark_out_format=json
//   build/bin/bench_self_collision --benchmark_filter=BM_Step/baraff_witkin
//       --benchmark_out=sc_bw.json --benchmark_out_format=json
//   scripts/self_collision_cost.py sc_se.json sc_bw.json
// Thickness: a quarter of the edge length, 0.25 / (N - 1) m. The material has the shipped
// draped-ball scenes' damping (0.0005 N s/m). The cloth is first draped with symplectic_euler
// WITH self_collision (the same thickness) for 0.35 s from the flat start (it has landed and
// folds start; 7 000 steps at 128^2, 126 s on one thread; 924 s at 256^2), cached as draped_sesc_N.bin; every run of both
// integrators starts from that state, which draped() checks has no intersecting triangle pair.
// LOOM_BENCH_DRAPE_TIME=T (seconds) drapes for T instead: a later state (at 1.7 s the cloth has
// settled on the ball and turns with it), cached as draped_sesc_N_tT.bin.
// Until 2026-11-29 the cloth was draped WITHOUT self_collision (draped_se_N.bin): that state
// was tangled (BM_StartState: 46 intersecting triangle pairs at 64^2, 1 420 at 128^2, layers
// 0.0002 thickness apart), so with self_collision switched on the response fought the
// crossings it cannot undo at every step (1 311 vertices moved per step at 128^2, all of them
// in or next to the tangle), which is what the figures of that time measured. Earlier still
// the bench draped with baraff_witkin (175 steps of 2 ms): at 128^2 that state was crumpled (1 % of the edges below 77 % of their
// length, the shortest at 16 %, against 95-105 % at 64^2): symplectic Euler with self_collision
// then held 320 000 pairs in its lists and made ~22 000 contact impulses per step, and with
// self_collision it also left vertices up to 3 mm inside the ball, which symplectic Euler's
// collider projection turned into kicks of 135 m/s. `impulses` counts the contact impulses per
// step, to show how many contacts were active.
#include <benchmark/benchmark.h>
#include <omp.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <set>
#include <utility>
#include <vector>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <functional>
#include <algorithm>
#include <map>
#include <memory>
#include <span>
#include <string>

#include "baraff_witkin.hpp"
#include "eigen_ldlt.hpp"
#include "eigen_pcg.hpp"
#ifdef LOOM_BENCH_CHOLMOD
#include "cholmod_solver.hpp"
#endif
#include "loom/forwarding_solver.hpp"
#include "loom/intersection_check.hpp"
#include "loom/mesh.hpp"
#include "loom/self_collision.hpp"
#include "common/plugin_loader.hpp"
#include "loom/simulation.hpp"

namespace {

constexpr double kDrapeTime = 0.35;  // s
// LOOM_BENCH_DRAPE_TIME=T (seconds) drapes for T instead (a later, more settled state; its
// cache files carry the time in their names).
double drape_time() {
  const char* t = std::getenv("LOOM_BENCH_DRAPE_TIME");
  return t ? std::atof(t) : kDrapeTime;
}
std::string drape_tag() {
  const char* t = std::getenv("LOOM_BENCH_DRAPE_TIME");
  return t ? std::string("_t") + t : std::string();
}
double se_dt(int n) { return 5.0e-5 * 127.0 / (n - 1); }

// integrator "baraff_witkin_sa_amg": baraff_witkin with the multilevel preconditioner (the
// solver a user picks for large cloth, docs/plugins/solvers.md) instead of block Jacobi.
std::string scene(int n, const std::string& integrator, bool self) {
  const bool sa_amg = integrator == "baraff_witkin_sa_amg";
  std::string s = "mesh: {grid: {nx: " + std::to_string(n) + ", ny: " + std::to_string(n) +
                  ", width: 1.0, height: 1.0, plane: xz}}\n" + R"(
material: {type: mass_spring, stencil: structural_shear_bend, stiffness: {structural: 200, shear: 200, bend: 20}, density: 0.1, damping: 0.0005}
)";
  s += sa_amg ? "solver: {type: filtered_pcg, filtered_pcg: {tolerance: 1.0e-5, preconditioner: sa_amg}}\n"
              : "solver: {type: eigen_pcg, eigen_pcg: {tolerance: 1.0e-5}}\n";
  s += R"(colliders: [{type: sphere, center: [0.5, -0.35, -0.5], radius: 0.3, thickness: 0.004, friction: 0.5,
             motion: {type: rotate, axis: [0, 1, 0], angular_velocity: 2.0}}]
)";
  // symplectic_euler: dt = 5e-5 is stable at 128 (scenes/draped_ball_symplectic_euler.yaml); it scales with the edge.
  const double dt_se = se_dt(n);
  s += integrator == "symplectic_euler" ? "integrator: {type: symplectic_euler, dt: " + std::to_string(dt_se) + "}\n"
                                        : "integrator: {type: baraff_witkin, dt: 2.0e-3}\n";
  if (self) s += "self_collision: {thickness: " + std::to_string(0.25 / (n - 1)) + ", friction: 0.3}\n";
  return s;
}

using loom_bench::loader;

// The draping takes a while at 256^2; LOOM_BENCH_DRAPE_CACHE=DIR keeps the draped positions
// and velocities there (draped_se_N.bin) for later runs of this benchmark.
bool read_cache(const std::string& path, loom::State& s) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::vector<double> x(s.x.size()), v(s.v.size());
  double t = 0;
  in.read(reinterpret_cast<char*>(x.data()), static_cast<std::streamsize>(x.size() * sizeof(double)));
  in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(v.size() * sizeof(double)));
  in.read(reinterpret_cast<char*>(&t), sizeof t);
  if (!in) return false;
  s.x = x;
  s.v = v;
  s.time = t;
  return true;
}

// The start state of every run: the flat cloth draped for kDrapeTime with symplectic_euler,
// WITH self_collision (the state a user's run would reach), cached as draped_sesc_N.bin. It is
// checked with the exact intersection count (loom/intersection_check.hpp), and refused if it has
// an intersecting pair. with_self = false gives the former start state (draped without
// self_collision, cached as draped_se_N.bin), which BM_StartState examines: it is tangled.
const loom::State& draped(int n, bool with_self = true) {
  static std::map<std::pair<int, bool>, std::unique_ptr<loom::Simulation>> sims;
  auto& sim = sims[{n, with_self}];
  if (!sim) {
    sim = loom::Simulation::from_string(scene(n, "symplectic_euler", with_self), "bench.yaml", ".", {}, loader());
    const char* dir = std::getenv("LOOM_BENCH_DRAPE_CACHE");
    const std::string name = (with_self ? "/draped_sesc_" : "/draped_se_") + std::to_string(n) + drape_tag() + ".bin";
    const std::string path = dir ? std::string(dir) + name : "";
    auto& s = sim->scene().state;
    if (path.empty() || !read_cache(path, s)) {
      const int steps = static_cast<int>(std::lround(drape_time() / se_dt(n)));
      for (int k = 0; k < steps; ++k) sim->step();
      if (!path.empty()) {
        std::ofstream out(path, std::ios::binary);
        out.write(reinterpret_cast<const char*>(s.x.data()), static_cast<std::streamsize>(s.x.size() * sizeof(double)));
        out.write(reinterpret_cast<const char*>(s.v.data()), static_cast<std::streamsize>(s.v.size() * sizeof(double)));
        out.write(reinterpret_cast<const char*>(&s.time), sizeof s.time);
      }
    }
    if (with_self) {
      const std::size_t bad = loom::count_intersecting_pairs(sim->scene().mesh, s.x);
      if (bad > 0) {
        std::fprintf(stderr, "bench_self_collision: the draped start state at %d^2 (%s) has %zu intersecting triangle pairs; delete the cache file and rerun\n",
                     n, path.empty() ? "not cached" : path.c_str(), bad);
        std::exit(2);
      }
    }
  }
  return sim->scene().state;
}

void BM_Step(benchmark::State& st, const std::string& integrator, bool self) {
  const int n = static_cast<int>(st.range(0));
  omp_set_num_threads(static_cast<int>(st.range(1)));
  loom::Simulation::set_notes(false);
  // The count in the scene too: `threads: auto` would choose its own (and adapt it during the run).
  const std::string threads = "threads=" + std::to_string(st.range(1));
  auto sim = loom::Simulation::from_string(scene(n, integrator, self), "bench.yaml", ".", {threads}, loader());
  sim->scene().state = draped(n);
  omp_set_num_threads(static_cast<int>(st.range(1)));  // draped() may have built an auto scene
  for (int k = 0; k < 3; ++k) sim->step();  // warm-up: work arrays and candidate lists sized
  double broad = 0, narrow = 0, response = 0, rebuilds = 0, full = 0, refreshed = 0, candidates = 0, impulses = 0;
  // The integrator's own search (baraff_witkin's self-contacts, SelfCollision::proximity_pairs),
  // inside the step: renewing the lists, and the pairs' filter and distances.
  double search_broad = 0, search_all = 0;
  const loom::SelfCollision* sc = sim->scene().self_collision.get();
  for (auto _ : st) {
    const double broad0 = sc ? sc->totals().search_broad_seconds : 0, all0 = sc ? sc->totals().search_seconds : 0;
    sim->step();
    if (sc) {
      search_broad += sc->totals().search_broad_seconds - broad0;
      search_all += sc->totals().search_seconds - all0;
      const auto& s = sc->last_stats();
      broad += s.broad_seconds;
      narrow += s.narrow_seconds;
      response += s.response_seconds;
      rebuilds += s.rebuilt ? 1 : 0;
      full += s.rebuilds;
      refreshed += static_cast<double>(s.refreshed);
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
    st.counters["search_broad_ms"] = C(1e3 * search_broad, C::kAvgIterations);
    st.counters["search_narrow_ms"] = C(1e3 * (search_all - search_broad), C::kAvgIterations);
    st.counters["rebuilds"] = C(rebuilds, C::kAvgIterations);
    st.counters["full_rebuilds"] = C(full, C::kAvgIterations);
    st.counters["refreshed"] = C(refreshed, C::kAvgIterations);
    st.counters["candidates"] = C(candidates, C::kAvgIterations);
    st.counters["impulses"] = C(impulses, C::kAvgIterations);
  }
}

// One-thread CPU time of the steps with self-collision, split by what the candidate lists did
// (full rebuild, refresh only, neither), from the draped state: the thread's own CPU clock
// (CLOCK_THREAD_CPUTIME_ID), so other processes on a shared machine add little. Run with
// one thread for a figure that does not depend on the machine's load:
//   LOOM_BENCH_DRAPE_CACHE=/tmp/loom_drape build/bin/bench_self_collision --benchmark_filter=BM_StepSplit
// Counters: ms per step of each kind of step and their share of the steps, ms of the step
// without self-collision on the same state (`without_ms`, same process), and the work counts
// per step (pairs in the lists, near pairs, impulses, broad-phase exact distance tests, CCD
// cubics solved), and the motion that renews the lists (fast_vertices: vertices that moved
// more than a quarter of the thickness in the step; largest_step_th: the largest displacement
// in the step, in thicknesses), per step. `other_broad_ms`, `other_narrow_ms`,
// `other_response_ms`: the self-collision phases of the steps that neither rebuilt nor refreshed
// their lists (the per-step pass alone: the reach check and the lists' frame, the near filter
// and proximity, the response).
double thread_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

void BM_StepSplit(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  const int steps = static_cast<int>(st.range(1));
  omp_set_num_threads(1);
  loom::Simulation::set_notes(false);
  double without = 0;
  {
    auto sim = loom::Simulation::from_string(scene(n, "symplectic_euler", false), "bench.yaml", ".", {}, loader());
    sim->scene().state = draped(n);
    for (int k = 0; k < 3; ++k) sim->step();
    const double t0 = thread_cpu_seconds();
    for (int k = 0; k < steps; ++k) sim->step();
    without = (thread_cpu_seconds() - t0) / steps;
  }
  double t_full = 0, t_refresh = 0, t_other = 0;
  double n_full = 0, n_refresh = 0, n_other = 0;
  double other_broad = 0, other_narrow = 0, other_response = 0;  // phases of the steps that keep their lists
  double candidates = 0, near = 0, impulses = 0, exact = 0, refreshed = 0, full = 0, ccd = 0, fast = 0, largest = 0;
  const double quarter = 0.25 * 0.25 / (n - 1);  // a quarter of the scene's thickness, m
  std::vector<double> before;
  for (auto _ : st) {
    auto sim = loom::Simulation::from_string(scene(n, "symplectic_euler", true), "bench.yaml", ".", {}, loader());
    sim->scene().state = draped(n);
    for (int k = 0; k < 3; ++k) sim->step();
    for (int k = 0; k < steps; ++k) {
      before = sim->scene().state.x;  // outside the timed part
      const double t0 = thread_cpu_seconds();
      sim->step();
      const double dt = thread_cpu_seconds() - t0;
      {
        const std::vector<double>& x = sim->scene().state.x;
        double big = 0;
        for (std::size_t i = 0; i < x.size() / 3; ++i) {
          double d2 = 0;
          for (int c = 0; c < 3; ++c) d2 += (x[3 * i + c] - before[3 * i + c]) * (x[3 * i + c] - before[3 * i + c]);
          fast += d2 > quarter * quarter ? 1 : 0;
          big = std::max(big, d2);
        }
        largest += std::sqrt(big) / (4 * quarter);
      }
      const auto& s = sim->scene().self_collision->last_stats();
      if (s.rebuilds > 0) {
        t_full += dt, ++n_full;
      } else if (s.refreshed > 0) {
        t_refresh += dt, ++n_refresh;
      } else {
        t_other += dt, ++n_other;
        other_broad += s.broad_seconds, other_narrow += s.narrow_seconds, other_response += s.response_seconds;
      }
      candidates += static_cast<double>(s.candidates_vt + s.candidates_ee);
      near += static_cast<double>(s.near);
      impulses += static_cast<double>(s.proximity + s.ccd_collisions);
      exact += static_cast<double>(s.exact_tests);
      ccd += static_cast<double>(s.ccd_tests);
      refreshed += static_cast<double>(s.refreshed);
      full += s.rebuilds;
    }
  }
  const double total = static_cast<double>(st.iterations()) * steps;
  st.counters["without_ms"] = 1e3 * without;
  st.counters["with_ms"] = 1e3 * (t_full + t_refresh + t_other) / total;
  st.counters["ratio"] = (t_full + t_refresh + t_other) / total / without;
  st.counters["full_step_ms"] = n_full > 0 ? 1e3 * t_full / n_full : 0;
  st.counters["refresh_step_ms"] = n_refresh > 0 ? 1e3 * t_refresh / n_refresh : 0;
  st.counters["other_step_ms"] = n_other > 0 ? 1e3 * t_other / n_other : 0;
  st.counters["other_broad_ms"] = n_other > 0 ? 1e3 * other_broad / n_other : 0;
  st.counters["other_narrow_ms"] = n_other > 0 ? 1e3 * other_narrow / n_other : 0;
  st.counters["other_response_ms"] = n_other > 0 ? 1e3 * other_response / n_other : 0;
  st.counters["full_share"] = n_full / total;
  st.counters["refresh_share"] = n_refresh / total;
  st.counters["full_rebuilds"] = full / total;
  st.counters["refreshed"] = refreshed / total;
  st.counters["candidates"] = candidates / total;
  st.counters["near"] = near / total;
  st.counters["impulses"] = impulses / total;
  st.counters["exact_tests"] = exact / total;
  st.counters["ccd_tests"] = ccd / total;
  // Why the lists churn: vertices that moved more than a quarter of the thickness in a step (a
  // vertex leaves its reach, at least half the thickness, within two such steps), and the
  // largest displacement of a step in thicknesses, both per step.
  st.counters["fast_vertices"] = fast / total;
  st.counters["largest_step_th"] = largest / total;
}
BENCHMARK(BM_StepSplit)->Args({64, 2000})->Args({128, 500})->Iterations(1)->Unit(benchmark::kMillisecond);

// What the start state is like, and whether the self-collision response fights it (no timing:
// counters only). Second argument: 0 = the former start state (draped WITHOUT self_collision,
// draped_se_N.bin), 1 = the current one (draped with it, draped_sesc_N.bin). Counters:
// `intersecting` triangle pairs (exact, loom/intersection_check.hpp, independent of the
// collision code) and the vertices of those triangles (`tangle_vertices`); vertex-triangle and
// edge-edge pairs closer than the thickness (`close_vt`, `close_ee`, through
// SelfCollision::proximity_pairs) and the smallest such distance over the thickness
// (`min_dist_over_th`); then `steps` symplectic_euler steps with self_collision, each compared
// with the step without self_collision from the same state (same process, one thread), so a
// vertex whose end of step differs is one the response moved: `moved_per_step`, `fighting`
// (moved in at least half the steps), `fighting_in_tangle` (of those, how many belong to an
// intersecting triangle pair or to a pair closer than half the thickness, at the start, or are
// an edge neighbour of such a vertex), and the largest start speed of a fighting vertex.
//   LOOM_BENCH_DRAPE_CACHE=/tmp/loom_drape build/bin/bench_self_collision --benchmark_filter=BM_StartState
void BM_StartState(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  const bool with_self = st.range(1) != 0;
  const int steps = static_cast<int>(st.range(2));
  omp_set_num_threads(1);
  loom::Simulation::set_notes(false);
  const loom::State s0 = draped(n, with_self);
  omp_set_num_threads(1);
  auto with = loom::Simulation::from_string(scene(n, "symplectic_euler", true), "bench.yaml", ".", {"threads=1"}, loader());
  auto without = loom::Simulation::from_string(scene(n, "symplectic_euler", false), "bench.yaml", ".", {"threads=1"}, loader());
  omp_set_num_threads(1);
  const loom::Mesh& mesh = with->scene().mesh;
  const auto nv = static_cast<std::size_t>(mesh.num_vertices());
  const double th = with->scene().self_collision->options().thickness;
  // The start state's tangle.
  std::vector<std::array<loom::Index, 2>> pairs;
  const std::size_t intersecting = loom::count_intersecting_pairs(mesh, s0.x, &pairs);
  std::vector<char> tangle(nv, 0);
  for (const auto& p : pairs)
    for (const loom::Index t : p)
      for (int j = 0; j < 3; ++j) tangle[mesh.triangles[3 * t + j]] = 1;
  const double tangle_vertices = static_cast<double>(std::count(tangle.begin(), tangle.end(), 1));
  loom::SelfCollision probe(with->scene().self_collision->options(), mesh);
  std::vector<loom::SelfCollision::Proximity> vt, ee;
  probe.proximity_pairs(s0.x.data(), th, vt, ee);
  double min_dist = th;
  for (const auto& p : vt) {
    min_dist = std::min(min_dist, p.distance);
    if (p.distance < 0.5 * th) {
      tangle[p.a] = 1;
      for (int j = 0; j < 3; ++j) tangle[mesh.triangles[3 * p.b + j]] = 1;
    }
  }
  for (const auto& p : ee) min_dist = std::min(min_dist, p.distance);
  std::vector<char> near_tangle = tangle;  // and their edge neighbours
  for (std::size_t t = 0; t < mesh.triangles.size() / 3; ++t)
    for (int j = 0; j < 3; ++j)
      if (tangle[mesh.triangles[3 * t + j]])
        for (int k = 0; k < 3; ++k) near_tangle[mesh.triangles[3 * t + k]] = 1;
  // Which vertices the response moves, step after step.
  std::vector<int> moved(nv, 0);
  double moved_total = 0;
  with->scene().state = s0;
  with->accept_state();  // a tangled start on purpose: what it costs (the step would refuse it)
  for (auto _ : st) {
    for (int k = 0; k < steps; ++k) {
      without->scene().state = with->scene().state;
      with->step();
      without->step();
      const auto& a = with->scene().state.x;
      const auto& b = without->scene().state.x;
      for (std::size_t i = 0; i < nv; ++i)
        if (a[3 * i] != b[3 * i] || a[3 * i + 1] != b[3 * i + 1] || a[3 * i + 2] != b[3 * i + 2]) {
          ++moved[i];
          ++moved_total;
        }
    }
  }
  const int total = static_cast<int>(st.iterations()) * steps;
  double fighting = 0, in_tangle = 0, vmax = 0;
  for (std::size_t i = 0; i < nv; ++i) {
    if (2 * moved[i] < total) continue;
    ++fighting;
    in_tangle += near_tangle[i] ? 1 : 0;
    const double* v = &s0.v[3 * i];
    vmax = std::max(vmax, std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]));
  }
  st.counters["intersecting"] = static_cast<double>(intersecting);
  st.counters["tangle_vertices"] = tangle_vertices;
  st.counters["close_vt"] = static_cast<double>(vt.size());
  st.counters["close_ee"] = static_cast<double>(ee.size());
  st.counters["min_dist_over_th"] = min_dist / th;
  st.counters["moved_per_step"] = moved_total / total;
  st.counters["fighting"] = fighting;
  st.counters["fighting_in_tangle"] = in_tangle;
  st.counters["fighting_vmax"] = vmax;
}
BENCHMARK(BM_StartState)->ArgsProduct({{64, 128}, {0, 1}, {40}})->Iterations(1)->Unit(benchmark::kMillisecond);

// Where a baraff_witkin step with self-collision spends its time (one thread, the thread's CPU
// clock per step; the phases inside the step are the integrator's and the self-collision
// code's own steady-clock timers, so read them as shares): from the draped state, `steps`
// steps of the scene's cloth stepped by a linked BaraffWitkin (defaults: implicit self-contact
// on) followed by the after-step response, as Simulation::step does. Counters per step:
// without_ms (the same state and scene without self_collision), with_ms, the integrator's step
// (bw_ms) split into find_ms (the pairs and contacts: SelfCollision::proximity_pairs and the
// contact set), pattern_ms (pattern extensions), spring_solve_ms (the solves with springs),
// the rest of the step; resolve_ms (the after-step response) split into broad/narrow/response;
// and work counts: contacts, solves with springs, their iterations and the first solve's,
// pattern_growths, candidates.
//   OMP_NUM_THREADS=1 LOOM_BENCH_DRAPE_CACHE=/tmp/loom_drape build/bin/bench_self_collision --benchmark_filter=BM_BwStepSplit
void BM_BwStepSplit(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  const int steps = static_cast<int>(st.range(1));
  omp_set_num_threads(1);
  loom::Simulation::set_notes(false);
  const double h = 2.0e-3;
  double without = 0;
  {
    auto sim = loom::Simulation::from_string(scene(n, "baraff_witkin", false), "bench.yaml", ".", {"threads=1"}, loader());
    sim->scene().state = draped(n);
    omp_set_num_threads(1);
    for (int k = 0; k < 2; ++k) sim->step();
    const double t0 = thread_cpu_seconds();
    for (int k = 0; k < steps; ++k) sim->step();
    without = (thread_cpu_seconds() - t0) / steps;
  }
  double with = 0, bw_t = 0, resolve = 0, find = 0, pattern = 0, spring_solve = 0, broad = 0, narrow = 0, response = 0;
  double pairs_t = 0, pairs = 0, material_blocks = 0, pattern_blocks = 0;
  double released = 0;
  double contacts = 0, solves = 0, spring_its = 0, all_its = 0, growths = 0, candidates = 0, impulses = 0;
  double find_lists = 0, resolve_lists = 0, near = 0, ccd_passes = 0, ccd_tests = 0, frozen = 0, refreshed = 0;
  for (auto _ : st) {
    auto sim = loom::Simulation::from_string(scene(n, "baraff_witkin", true), "bench.yaml", ".", {"threads=1"}, loader());
    omp_set_num_threads(1);
    loom::Scene& sc = sim->scene();
    sc.state = draped(n);
    loom::BaraffWitkin bw;
    bw.prepare(sc, h);
    auto one = [&](bool count) {
      const double t0 = thread_cpu_seconds();
      sc.self_collision->begin_step(sc.state);
      const int g0 = bw.pattern_rebuilds();
      const int lists0 = sc.self_collision->last_stats().rebuilds;
      bw.step(sc, h);
      const int lists1 = sc.self_collision->last_stats().rebuilds;  // + those of proximity_pairs
      const double t1 = thread_cpu_seconds();
      sc.self_collision->resolve(sc.state, h);
      const double t2 = thread_cpu_seconds();
      if (!count) return;
      with += t2 - t0;
      bw_t += t1 - t0;
      resolve += t2 - t1;
      const auto& c = bw.self_contact()->stats();
      find += c.find_seconds;
      pairs_t += c.pairs_seconds;
      pairs += c.pairs;
      pattern += c.pattern_seconds;
      spring_solve += c.solve_seconds;
      contacts += c.contacts;
      released += c.released;
      solves += c.solves;
      spring_its += c.iterations;
      all_its += bw.last_step().linear_iterations;
      growths += bw.pattern_rebuilds() - g0;
      const auto& s = sc.self_collision->last_stats();
      broad += s.broad_seconds;
      narrow += s.narrow_seconds;
      response += s.response_seconds;
      candidates += static_cast<double>(s.candidates_vt + s.candidates_ee);
      impulses += static_cast<double>(s.proximity + s.ccd_collisions);
      find_lists += lists1 - lists0;
      resolve_lists += s.rebuilds;
      near += static_cast<double>(s.near);
      ccd_passes += s.ccd_iterations;
      ccd_tests += static_cast<double>(s.ccd_tests);
      frozen += static_cast<double>(s.frozen);
      refreshed += static_cast<double>(s.refreshed);
    };
    material_blocks = static_cast<double>(bw.pattern().nnz_blocks());
    for (int k = 0; k < 2; ++k) one(false);
    for (int k = 0; k < steps; ++k) one(true);
    pattern_blocks = static_cast<double>(bw.pattern().nnz_blocks());
  }
  const double total = static_cast<double>(st.iterations()) * steps;
  st.counters["without_ms"] = 1e3 * without;
  st.counters["with_ms"] = 1e3 * with / total;
  st.counters["bw_ms"] = 1e3 * bw_t / total;
  st.counters["find_ms"] = 1e3 * find / total;
  st.counters["pairs_ms"] = 1e3 * pairs_t / total;
  st.counters["pairs"] = pairs / total;
  st.counters["pattern_ms"] = 1e3 * pattern / total;
  st.counters["spring_solve_ms"] = 1e3 * spring_solve / total;
  st.counters["resolve_ms"] = 1e3 * resolve / total;
  st.counters["broad_ms"] = 1e3 * broad / total;
  st.counters["narrow_ms"] = 1e3 * narrow / total;
  st.counters["response_ms"] = 1e3 * response / total;
  st.counters["contacts"] = contacts / total;
  st.counters["released"] = released / total;
  st.counters["solves"] = solves / total;
  st.counters["spring_its"] = spring_its / total;
  st.counters["first_its"] = (all_its - spring_its) / total;
  st.counters["pattern_growths"] = growths / total;
  st.counters["material_blocks"] = static_cast<double>(material_blocks);
  st.counters["pattern_blocks"] = static_cast<double>(pattern_blocks);
  st.counters["candidates"] = candidates / total;
  st.counters["impulses"] = impulses / total;
  // Work of the candidate lists and the after-step response, per step: full rebuilds in
  // find() (proximity_pairs) and in resolve(), vertices refreshed by resolve(), pairs of the
  // lists that resolve() treats as near, CCD passes, CCD cubics solved, frozen vertices.
  st.counters["find_rebuilds"] = find_lists / total;
  st.counters["resolve_rebuilds"] = resolve_lists / total;
  st.counters["refreshed"] = refreshed / total;
  st.counters["near"] = near / total;
  st.counters["ccd_passes"] = ccd_passes / total;
  st.counters["ccd_tests"] = ccd_tests / total;
  st.counters["frozen"] = frozen / total;
}
BENCHMARK(BM_BwStepSplit)->Args({64, 40})->Args({128, 12})->Args({256, 2})->Iterations(1)->Unit(benchmark::kMillisecond);

// The multilevel preconditioner with self-contact springs: baraff_witkin + filtered_pcg with
// preconditioner sa_amg (tolerance 1e-5, one thread), from the draped state, the springs either
// assembled into A (mode 0: the pattern is extended when a contact needs blocks it lacks, and
// the hierarchy is then rebuilt from scratch) or applied matrix-free (the outer PCG applies
// A + E; E's diagonal blocks on level 0 of the hierarchy built once from A's pattern: mode 1
// on every level through the Galerkin products, mode 2 on level 0 only). Counters per step:
// step_ms (thread CPU time of the integrator's step and the after-step response), bw_ms (the
// integrator's step), amg_setup_ms (hierarchy set-ups and level-0 refreshes; amg_factorizes of
// them per step, amg_full_setups of the whole hierarchy), iterations (every solve of the step),
// spring_its (those of the solves after the springs were found, friction's included), solves
// (with springs, before the friction dampers), friction_solves (with dampers), contacts, pattern_growths;
// intersections at the end (exact count). Last argument: implicit_friction (1, the default:
// friction inside the solve, up to 3 more solves per step; 0: the correction after it).
//   OMP_NUM_THREADS=1 LOOM_BENCH_DRAPE_CACHE=/tmp/loom_drape build/bin/bench_self_collision --benchmark_filter=BM_BwSaAmgContact
class AssembledOnly final : public loom::ForwardingSolver {  // hides set_extra_operator: the integrator assembles
 public:
  using ForwardingSolver::ForwardingSolver;
  bool supports_extra_operator() const override { return false; }
  void set_extra_operator(const loom::ExtraOperator*) override {}
};

// What both contact benches below tally per counted step: thread CPU time of the integrator's
// step (bw) and of it with the after-step response (step), the step's linear iterations, the
// self-contact springs' solves, iterations and contacts, the solves with friction dampers,
// pattern growths, the friction's excess over Coulomb's bounds; intersections at the end (exact count).
struct BwContactTally {
  double step_t = 0, bw_t = 0, its = 0, spring_its = 0, solves = 0, friction_solves = 0, contacts = 0, growths = 0,
         intersections = 0, col_excess = 0, pair_excess = 0, col_steps = 0, pair_steps = 0;
  // One step of `bw` with self-collision's begin_step and resolve around it; tallied when `counted`.
  void step(loom::Scene& sc, loom::BaraffWitkin& bw, double h, bool counted) {
    const int g0 = bw.pattern_rebuilds();
    const long long f0 = bw.friction_solves();
    const double t0 = thread_cpu_seconds();
    sc.self_collision->begin_step(sc.state);
    bw.step(sc, h);
    const double t1 = thread_cpu_seconds();
    sc.self_collision->resolve(sc.state, h);
    const double t2 = thread_cpu_seconds();
    if (!counted) return;
    step_t += t2 - t0;
    bw_t += t1 - t0;
    const auto& c = bw.self_contact()->stats();
    its += bw.last_step().linear_iterations;
    spring_its += c.iterations;
    solves += c.solves;
    friction_solves += static_cast<double>(bw.friction_solves() - f0);
    contacts += c.contacts;
    growths += bw.pattern_rebuilds() - g0;
    if (bw.collider_friction().contacts > 0) {
      col_excess += bw.collider_friction().relative_excess();
      col_steps += 1;
    }
    if (bw.pair_friction().contacts > 0) {
      pair_excess += bw.pair_friction().relative_excess();
      pair_steps += 1;
    }
  }
  void report(benchmark::State& st, double total) const {
    st.counters["step_ms"] = 1e3 * step_t / total;
    st.counters["bw_ms"] = 1e3 * bw_t / total;
    st.counters["iterations"] = its / total;
    st.counters["spring_its"] = spring_its / total;
    st.counters["solves"] = solves / total;
    st.counters["friction_solves"] = friction_solves / total;
    st.counters["contacts"] = contacts / total;
    st.counters["pattern_growths"] = growths / total;
    st.counters["intersections"] = intersections;
    // After each step's last solve with dampers, the friction impulses' excess over their
    // Coulomb bounds relative to the bounds' sum (FrictionTally::relative_excess), mean over the
    // steps with such contacts: collider contacts, self-contact pairs.
    st.counters["col_excess"] = col_steps > 0 ? col_excess / col_steps : 0.0;
    st.counters["pair_excess"] = pair_steps > 0 ? pair_excess / pair_steps : 0.0;
  }
};

void BM_BwSaAmgContact(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  const int mode = static_cast<int>(st.range(1));
  const int steps = static_cast<int>(st.range(2));
  loom::BaraffWitkinOptions bo;
  bo.implicit_friction = st.range(3) != 0;  // friction inside the solve (the default) or after it
  omp_set_num_threads(1);
  loom::Simulation::set_notes(false);
  const double h = 2.0e-3;
  BwContactTally tally;
  double setup = 0, full_setups = 0, factorizes = 0;
  for (auto _ : st) {
    auto sim = loom::Simulation::from_string(scene(n, "baraff_witkin", true), "bench.yaml", ".", {"threads=1"}, loader());
    omp_set_num_threads(1);
    loom::Scene& sc = sim->scene();
    sc.state = draped(n);
    loom::PcgOptions o;
    o.preconditioner = loom::PcgPreconditioner::SaAmg;
    o.tolerance = 1e-5;
    o.amg.extra_on_coarse_levels = mode != 2;
    auto pcg = std::make_unique<loom::EigenPcg>(o);
    loom::EigenPcg* amg = pcg.get();
    if (mode == 0)
      sc.solver = std::make_unique<AssembledOnly>(std::move(pcg));
    else
      sc.solver = std::move(pcg);
    loom::BaraffWitkin bw(bo);
    bw.prepare(sc, h);
    if (bw.self_contact_matrix_free() != (mode != 0)) {
      st.SkipWithError("the springs' path is not the one asked for");
      return;
    }
    auto one = [&](bool count) {
      const double s0 = amg->amg() ? amg->amg()->timings().setup : 0.0;
      const int f0 = amg->amg() ? amg->amg()->refreshes() : 0;
      const long c0 = amg->amg() ? amg->amg()->timings().setups : 0;
      tally.step(sc, bw, h, count);
      if (!count) return;
      setup += amg->amg()->timings().setup - s0;
      full_setups += amg->amg()->refreshes() - f0;
      factorizes += static_cast<double>(amg->amg()->timings().setups - c0);
    };
    for (int k = 0; k < 2; ++k) one(false);
    for (int k = 0; k < steps; ++k) one(true);
    tally.intersections = static_cast<double>(loom::count_intersecting_pairs(sc.mesh, sc.state.x));
  }
  const double total = static_cast<double>(st.iterations()) * steps;
  tally.report(st, total);
  st.counters["amg_setup_ms"] = 1e3 * setup / total;
  st.counters["amg_full_setups"] = full_setups / total;  // of the hierarchy (the rest refresh level 0's diagonal)
  st.counters["amg_factorizes"] = factorizes / total;
}
BENCHMARK(BM_BwSaAmgContact)->ArgsProduct({{64, 128}, {0, 1, 2}, {12}, {1, 0}})->Iterations(1)->Unit(benchmark::kMillisecond);

// The direct solvers with self-contact springs: baraff_witkin + eigen_ldlt (second argument 0)
// or cholmod (1, when built), one thread, from the draped state, the springs assembled into A
// (third argument 0: the pattern is extended when a contact needs blocks it lacks, the solver
// analyses it again, and every solve refactors A + E) or `contact_springs:
// factor_preconditioned_pcg` (1: A alone factored, once per step, A + E solved by PCG with that
// factor, tolerance 1e-10). Counters per step: step_ms, bw_ms (as BM_BwSaAmgContact),
// factorizations (numeric), iterations (every solve; 1 per direct solve), spring_its (those of
// the solves with springs), solves (with springs), contacts, pattern_growths; intersections at
// the end.
//   OMP_NUM_THREADS=1 LOOM_BENCH_DRAPE_CACHE=/tmp/loom_drape build/bin/bench_self_collision --benchmark_filter=BM_BwDirectContact
void BM_BwDirectContact(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  const int which = static_cast<int>(st.range(1));
  const bool factor_pcg = st.range(2) != 0;
  const int steps = static_cast<int>(st.range(3));
  // contact_max_iterations (default 1000; $LOOM_BENCH_CONTACT_MAXIT overrides it)
  const char* mi = std::getenv("LOOM_BENCH_CONTACT_MAXIT");
  omp_set_num_threads(1);
  loom::Simulation::set_notes(false);
  const double h = 2.0e-3;
  BwContactTally tally;
  double facts = 0, max_solve_its = 0;
  for (auto _ : st) {
    auto sim = loom::Simulation::from_string(scene(n, "baraff_witkin", true), "bench.yaml", ".", {"threads=1"}, loader());
    omp_set_num_threads(1);
    loom::Scene& sc = sim->scene();
    sc.state = draped(n);
    std::function<int()> count;
    if (which == 0) {
      loom::LdltOptions o;
      if (factor_pcg) o.contact_springs = "factor_preconditioned_pcg";
      if (mi) o.contact_max_iterations = std::atoi(mi);
      auto s = std::make_unique<loom::EigenLdlt>(o);
      loom::EigenLdlt* p = s.get();
      count = [p] { return p->numeric_factorizations(); };
      sc.solver = std::move(s);
    } else {
#ifdef LOOM_BENCH_CHOLMOD
      loom::CholmodOptions o;
      o.blas_threads = 1;
      if (factor_pcg) o.contact_springs = "factor_preconditioned_pcg";
      if (mi) o.contact_max_iterations = std::atoi(mi);
      auto s = std::make_unique<loom::CholmodSolver>(o);
      loom::CholmodSolver* p = s.get();
      count = [p] { return p->numeric_factorizations(); };
      sc.solver = std::move(s);
#else
      st.SkipWithError("cholmod not built");
      return;
#endif
    }
    loom::BaraffWitkin bw;
    bw.prepare(sc, h);
    if (bw.self_contact_matrix_free() != factor_pcg) {
      st.SkipWithError("the springs' path is not the one asked for");
      return;
    }
    auto one = [&](bool counted) {
      const int f0 = count();
      tally.step(sc, bw, h, counted);
      if (!counted) return;
      facts += count() - f0;
      max_solve_its = std::max(max_solve_its, static_cast<double>(bw.last_step().linear_iterations));
    };
    for (int k = 0; k < 2; ++k) one(false);
    for (int k = 0; k < steps; ++k) one(true);
    tally.intersections = static_cast<double>(loom::count_intersecting_pairs(sc.mesh, sc.state.x));
  }
  const double total = static_cast<double>(st.iterations()) * steps;
  tally.report(st, total);
  st.counters["factorizations"] = facts / total;
  st.counters["max_step_its"] = max_solve_its;  // the most iterations of one step
}
BENCHMARK(BM_BwDirectContact)->ArgsProduct({{64, 128}, {0, 1}, {0, 1}, {12}})->Iterations(1)->Unit(benchmark::kMillisecond);

// ---------------------------------------------------------------------------------------------
// Broad phase alone, BVH against a uniform-grid spatial hash, on the draped cloth: find every
// pair of triangles whose boxes overlap, the boxes grown by the thickness on each side (what a
// full rebuild of the candidate lists starts from: each vertex's reach is at least half the
// thickness, plus half the thickness as gap). Both count the same pairs (counter `pairs`;
// `agree` = 1 when the counts match).
// - bvh: the refit of SelfCollision's hierarchy (built once on the flat cloth), then its self
//   traversal (TriangleBvh::self_pairs), one thread.
// - hash: cells of 1 or 2 (second argument) times the mean box size, each box entered in the cells it overlaps (counting sort
//   into a table of 2^k buckets, k fixed by the box count), pairs tested within a cell and
//   reported by the cell holding the lower corner of their overlap (so once), one thread.

struct Boxes {
  std::vector<double> lo, hi;
  std::vector<double> centroid_rest;
};

Boxes draped_boxes(int n) {
  const loom::State& s = draped(n);
  const loom::Mesh mesh = loom::make_grid(n, n, 1.0, 1.0, loom::GridPlane::XZ);
  const loom::Index nt = mesh.num_triangles();
  const double pad = 0.25 / (n - 1);
  Boxes b;
  b.lo.resize(3 * nt);
  b.hi.resize(3 * nt);
  b.centroid_rest.assign(3 * nt, 0.0);
  for (loom::Index t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      double lo = 1e300, hi = -1e300;
      for (int j = 0; j < 3; ++j) {
        const loom::Index v = mesh.triangles[3 * t + j];
        lo = std::min(lo, s.x[3 * v + k]);
        hi = std::max(hi, s.x[3 * v + k]);
        b.centroid_rest[3 * t + k] += mesh.positions[3 * v + k] / 3.0;
      }
      b.lo[3 * t + k] = lo - pad;
      b.hi[3 * t + k] = hi + pad;
    }
  return b;
}

std::map<int, long> bvh_pairs_found;

void BM_BroadPhaseBvh(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  const Boxes b = draped_boxes(n);
  loom::selfcol::TriangleBvh bvh;
  bvh.build(b.centroid_rest);
  std::vector<std::array<loom::Index, 2>> stack;
  stack.reserve(256);
  long pairs = 0;
  for (auto _ : st) {
    bvh.refit(b.lo.data(), b.hi.data(), 0.0);
    pairs = 0;
    bvh.self_pairs([&](loom::Index, loom::Index) { ++pairs; }, stack);
    benchmark::DoNotOptimize(pairs);
  }
  bvh_pairs_found[n] = pairs;
  st.counters["pairs"] = static_cast<double>(pairs);
  st.counters["triangles"] = static_cast<double>(b.lo.size() / 3);
}

void BM_BroadPhaseHash(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  const Boxes b = draped_boxes(n);
  const std::size_t nt = b.lo.size() / 3;
  double mean = 0;
  for (std::size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) mean += (b.hi[3 * t + k] - b.lo[3 * t + k]) / (3.0 * nt);
  const double inv = 1.0 / (mean * static_cast<double>(st.range(1)));
  std::size_t buckets = 1;
  while (buckets < 4 * nt) buckets *= 2;
  struct Entry {
    std::int64_t cell;
    std::uint32_t tri;
  };
  auto key = [](std::int64_t i, std::int64_t j, std::int64_t k) {
    return ((i & 0x1FFFFF) << 42) | ((j & 0x1FFFFF) << 21) | (k & 0x1FFFFF);
  };
  auto bucket_of = [&](std::int64_t c) {
    return static_cast<std::size_t>((static_cast<std::uint64_t>(c) * 0x9E3779B97F4A7C15ull) >> 20) & (buckets - 1);
  };
  std::vector<Entry> entries, sorted;
  std::vector<std::uint32_t> start(buckets + 1);
  entries.reserve(16 * nt);
  sorted.reserve(16 * nt);
  long pairs = 0;
  for (auto _ : st) {
    entries.clear();
    for (std::size_t t = 0; t < nt; ++t) {
      std::int64_t lo[3], hi[3];
      for (int k = 0; k < 3; ++k) {
        lo[k] = static_cast<std::int64_t>(std::floor(b.lo[3 * t + k] * inv));
        hi[k] = static_cast<std::int64_t>(std::floor(b.hi[3 * t + k] * inv));
      }
      for (std::int64_t i = lo[0]; i <= hi[0]; ++i)
        for (std::int64_t j = lo[1]; j <= hi[1]; ++j)
          for (std::int64_t k = lo[2]; k <= hi[2]; ++k) entries.push_back({key(i, j, k), static_cast<std::uint32_t>(t)});
    }
    std::fill(start.begin(), start.end(), 0u);
    for (const Entry& e : entries) ++start[bucket_of(e.cell) + 1];
    for (std::size_t q = 0; q < buckets; ++q) start[q + 1] += start[q];
    sorted.resize(entries.size());
    for (const Entry& e : entries) sorted[start[bucket_of(e.cell)]++] = e;  // start[q] now = end of bucket q
    pairs = 0;
    std::uint32_t first = 0;
    for (std::size_t q = 0; q < buckets; ++q) {
      const std::uint32_t last = start[q];
      for (std::uint32_t x = first; x < last; ++x)
        for (std::uint32_t y = x + 1; y < last; ++y) {
          const Entry &A = sorted[x], &B = sorted[y];
          if (A.cell != B.cell || A.tri == B.tri) continue;
          const double* alo = &b.lo[3 * A.tri];
          const double* ahi = &b.hi[3 * A.tri];
          const double* blo = &b.lo[3 * B.tri];
          const double* bhi = &b.hi[3 * B.tri];
          bool ov = true;
          std::int64_t c[3];
          for (int k = 0; k < 3; ++k) {
            ov &= alo[k] <= bhi[k] && blo[k] <= ahi[k];
            c[k] = static_cast<std::int64_t>(std::floor(std::max(alo[k], blo[k]) * inv));
          }
          if (ov && key(c[0], c[1], c[2]) == A.cell) ++pairs;
        }
      first = last;
    }
    benchmark::DoNotOptimize(pairs);
  }
  st.counters["pairs"] = static_cast<double>(pairs);
  st.counters["triangles"] = static_cast<double>(nt);
  st.counters["entries_per_triangle"] = static_cast<double>(entries.size()) / static_cast<double>(nt);
  const auto it = bvh_pairs_found.find(n);
  if (it != bvh_pairs_found.end()) st.counters["agree"] = it->second == pairs ? 1 : 0;
}

BENCHMARK(BM_BroadPhaseBvh)->Arg(64)->Arg(128)->Arg(256)->Unit(benchmark::kMillisecond);

// One full rebuild of SelfCollision's candidate lists on the draped state, one thread:
// SelfCollision::min_distance within 2 thicknesses, which is the rebuild of a step in which every
// vertex has the smallest reach (th/2; gap th: boxes grown by th, exact distances below 2 th).
// CPU time per rebuild; counters: the pairs it lists and the exact distances it computed.
//   OMP_NUM_THREADS=1 LOOM_BENCH_DRAPE_CACHE=/tmp/loom_drape build/bin/bench_self_collision --benchmark_filter=BM_Rebuild
void BM_Rebuild(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  omp_set_num_threads(1);
  const loom::State& s = draped(n);
  omp_set_num_threads(1);
  const loom::Mesh mesh = loom::make_grid(n, n, 1.0, 1.0, loom::GridPlane::XZ);
  loom::SelfCollision::Options o;
  o.thickness = 0.25 / (n - 1);
  loom::SelfCollision sc(o, mesh);
  double m = 0;
  for (auto _ : st) {
    m = sc.min_distance(s.x, 2 * o.thickness);
    benchmark::DoNotOptimize(m);
  }
  std::vector<loom::SelfCollision::Proximity> vt, ee;
  sc.proximity_pairs(s.x.data(), 2 * o.thickness, vt, ee);
  st.counters["pairs"] = static_cast<double>(vt.size() + ee.size());
  st.counters["min_over_th"] = m / o.thickness;
}
BENCHMARK(BM_Rebuild)->Arg(64)->Arg(128)->Arg(256)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BroadPhaseHash)->ArgsProduct({{64, 128, 256}, {1, 2}})->Unit(benchmark::kMillisecond);

void args(benchmark::internal::Benchmark* b) {
  // Two threads (the machine the figures were taken on has two cores); LOOM_BENCH_THREADS=k overrides.
  const char* env = std::getenv("LOOM_BENCH_THREADS");
  const int threads = env ? std::max(1, std::atoi(env)) : 2;
  for (int n : {64, 128, 256}) b->Args({n, threads});
  // 2 s per row: rebuilds come every 10-15 explicit steps, so the default 0.5 s (about 40
  // steps at 128^2 with self-collision) sampled them poorly.
  b->MinTime(2.0)->Unit(benchmark::kMillisecond);
}

BENCHMARK_CAPTURE(BM_Step, symplectic_euler_without, std::string("symplectic_euler"), false)->Apply(args);
BENCHMARK_CAPTURE(BM_Step, symplectic_euler_self_collision, std::string("symplectic_euler"), true)->Apply(args);
BENCHMARK_CAPTURE(BM_Step, baraff_witkin_without, std::string("baraff_witkin"), false)->Apply(args);
BENCHMARK_CAPTURE(BM_Step, baraff_witkin_self_collision, std::string("baraff_witkin"), true)->Apply(args);
BENCHMARK_CAPTURE(BM_Step, baraff_witkin_sa_amg_without, std::string("baraff_witkin_sa_amg"), false)->Apply(args);
BENCHMARK_CAPTURE(BM_Step, baraff_witkin_sa_amg_self_collision, std::string("baraff_witkin_sa_amg"), true)->Apply(args);

}  // namespace

BENCHMARK_MAIN();
