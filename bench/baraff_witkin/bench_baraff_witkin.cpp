// One Baraff-Witkin step (assembly + solve) of the hanging wool cloth (gnatv, 10 m x 10 m,
// top corners pinned, h = 0.01, Kang-Cho c_d = 0.01 as in scenes/wool_hanging_32.yaml) with
// eigen_pcg (block Jacobi, relative residual 1e-5) and eigen_ldlt, on 32x32, 128x128 and
// 256x256 grids. The cloth is first advanced `warmup` steps from rest so the measured steps
// see a deformed, moving cloth. Counters: assembly and solve ms per step (forces +
// Jacobians + system vs factorize + solve), iterations per step, last relative residual.
//
// bw_solver/wool<n>/<solver>: the wool hang at 32^2 .. 512^2 for every CPU solver and
// preconditioner (eigen_pcg block_jacobi, eigen_pcg sa_amg with the rigid-body or translation
// near-null space and a prolongator (or the whole coarse hierarchy) rebuilt every step or every
// 10th, eigen_ldlt up to 128^2; *_cold: warm_start off, each solve from dv = 0; *_extrapolated:
// from 2 dv(n-1) - dv(n-2); *_saved: each system also solved from dv = 0, untimed, for the
// counter iters_saved = cold minus warm (or extrapolated) iterations per solve; *_sweeps2,
// *_coarse2, *_hierarchy2: cycle variants of NUMERICS.md 3.6; *_upperspmv: the PCG's SpMV from
// the upper triangle instead of the full rows; *_floatspmv: from a float copy of A;
// *_drop<t>, *_damp<d>, *_strength<t>: coarse_drop_tolerance, prolongator_damping and
// strength_threshold probes, docs/plugins/solvers.md "Issue 15, fifth pass"),
// with a timing wrapper around the solver: setup_ms (the first factorize: aggregation and
// patterns + values), factorize_ms and solve_ms per step, iters per step, step_ms.
//   bench_baraff_witkin --benchmark_filter=bw_solver --benchmark_counters_tabular=true
//   LOOM_BENCH_SIZES=32,64,128,256,512 (default) selects the grids.
#include <benchmark/benchmark.h>

#include <dlfcn.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "baraff_witkin.hpp"
#include "eigen_ldlt.hpp"
#include "eigen_pcg.hpp"
#include "gnatv_material.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "loom/registry.hpp"
#include "loom/scene.hpp"
#include "loom/simulation.hpp"

namespace {

// A LinearSolver that times another one (first factorize = set-up, then per step).
class Timed final : public loom::LinearSolver {
 public:
  explicit Timed(std::unique_ptr<loom::LinearSolver> s) : s_(std::move(s)) {}
  std::string name() const override { return s_->name(); }
  void analyze_pattern(const loom::BsrMatrix& A, const loom::Filter& S) override { s_->analyze_pattern(A, S); }
  void set_coordinates(std::span<const double> x) override { s_->set_coordinates(x); }
  bool factorize(const loom::BsrMatrix& A, const loom::Filter& S, loom::SolveReport& r) override {
    const auto t0 = std::chrono::steady_clock::now();
    const bool ok = s_->factorize(A, S, r);
    const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (factorizations++ == 0) setup = t;
    else factorize_total += t;
    return ok;
  }
  loom::SolveReport solve(const loom::BsrMatrix& A, const loom::Filter& S, std::span<const double> b,
                          std::span<const double> z, std::span<double> dv) override {
    // Linear extrapolation of the initial guess from the last two solutions (2 dv1 - dv0)
    // instead of the integrator's warm start (dv1): measured here, not in the integrator.
    if (extrapolate && prev0.size() == dv.size())
      for (std::size_t k = 0; k < dv.size(); ++k) dv[k] = 2 * prev1[k] - prev0[k];
    if (measure_saved) {
      // The same system solved from dv = 0 (the cold start) first, untimed: the difference of
      // the iteration counts is what the warm (or extrapolated) start saved in this step.
      const auto tc = std::chrono::steady_clock::now();
      cold.assign(dv.size(), 0.0);
      cold_iterations += s_->solve(A, S, b, z, cold).iterations;
      untimed += std::chrono::duration<double>(std::chrono::steady_clock::now() - tc).count();
    }
    const auto t0 = std::chrono::steady_clock::now();
    loom::SolveReport r = s_->solve(A, S, b, z, dv);
    if (extrapolate) {
      if (prev1.size() == dv.size()) prev0 = prev1;
      prev1.assign(dv.begin(), dv.end());
    }
    solve_total += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    iterations += r.iterations;
    ++solves;
    return r;
  }
  void reset_counts() { factorize_total = solve_total = untimed = 0; iterations = cold_iterations = 0; solves = 0; }
  double setup = 0, factorize_total = 0, solve_total = 0, untimed = 0;
  long iterations = 0, solves = 0, factorizations = 0, cold_iterations = 0;
  bool extrapolate = false, measure_saved = false;
  std::vector<double> prev0, prev1, cold;

 private:
  std::unique_ptr<loom::LinearSolver> s_;
};

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

struct SolverVariant {
  std::string name;
  bool ldlt = false;
  loom::PcgOptions pcg;
  int max_n = 1 << 30;
  bool warm_start = true;  // BaraffWitkinOptions::warm_start (start from the previous dv)
  bool extrapolate = false;  // start from 2 dv(n-1) - dv(n-2) instead
  bool measure_saved = false;  // also solve from dv = 0 (untimed): counter iters_saved
};

std::vector<SolverVariant> variants() {
  std::vector<SolverVariant> v;
  loom::PcgOptions bj;
  bj.tolerance = 1e-5;
  bj.max_iterations = 100000;
  // Skipped above a size (max_n): block Jacobi at 512^2 (about 1500 iterations, ~3 s a step:
  // the set would not fit in minutes), the warm-start comparisons above 256^2 (they measure
  // iteration counts, which the smaller grids already show), eigen_ldlt above 128^2 (2.7 s a
  // step at 256^2).
  v.push_back({"eigen_pcg_block_jacobi", false, bj, 256});
  v.push_back({"eigen_pcg_block_jacobi_cold", false, bj, 256, false});
  v.push_back({"eigen_pcg_block_jacobi_extrapolated", false, bj, 256, true, true});
  loom::PcgOptions amg = bj;
  amg.preconditioner = loom::PcgPreconditioner::SaAmg;
  amg.amg.prolongator_refresh_steps = 1;
  v.push_back({"eigen_pcg_sa_amg_rigid", false, amg});
  v.push_back({"eigen_pcg_sa_amg_rigid_cold", false, amg, 256, false});
  v.push_back({"eigen_pcg_sa_amg_rigid_extrapolated", false, amg, 256, true, true});
  amg.amg.prolongator_refresh_steps = 10;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10", false, amg});
  // iters_saved per solve by the warm start and by the extrapolated start (each step also
  // solved from dv = 0, untimed and subtracted from step_ms).
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_saved", false, amg, 1 << 30, true, false, true});
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_extrapolated_saved", false, amg, 1 << 30, true, true, true});
  // The PCG's SpMV from the upper triangle instead of the full rows (A/B of upper_spmv.hpp).
  amg.upper_triangle_spmv = true;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_upperspmv", false, amg});
  amg.upper_triangle_spmv = false;
  // The PCG's SpMV from a float copy of A (float_spmv.hpp): half the matrix bytes of the SpMV.
  amg.float_spmv = true;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_floatspmv", false, amg});
  amg.float_spmv = false;
  // Cycle variants (issue 15, NUMERICS.md 3.6): a second Gauss-Seidel sweep on every level or
  // on the coarse levels only, and the coarse levels recomputed every 2nd step.
  amg.amg.smoothing_sweeps = 2;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_sweeps2", false, amg});
  amg.amg.smoothing_sweeps = 1;
  amg.amg.coarse_smoothing_sweeps = 2;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_coarse2", false, amg});
  amg.amg.coarse_smoothing_sweeps = 0;
  amg.amg.hierarchy_refresh_steps = 2;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_hierarchy2", false, amg});
  amg.amg.hierarchy_refresh_steps = 1;
  amg.amg.aggressive_levels = 1;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_aggressive1", false, amg});
  amg.amg.aggressive_levels = 2;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_aggressive2", false, amg});
  amg.amg.aggressive_levels = 0;
  // Sparser coarse levels (coarse_drop_tolerance, issue 15): weak Galerkin blocks dropped,
  // diagonal blocks scaled to keep every level SPD.
  for (const char* d : {"0.02", "0.05", "0.1", "0.2"}) {
    amg.amg.coarse_drop_tolerance = std::stod(d);
    v.push_back({std::string("eigen_pcg_sa_amg_rigid_refresh10_drop") + d, false, amg});
  }
  amg.amg.coarse_drop_tolerance = 0;
  // Block SOR smoothing (issue 15): weights against Gauss-Seidel (the default; `_gs` names it
  // explicitly), on every level or (coarse1: weight 1.5) level 0 only.
  for (const char* w : {"1.0", "1.3", "1.5", "1.6", "1.7"}) {
    amg.amg.smoothing_relaxation = std::stod(w);
    v.push_back({std::string("eigen_pcg_sa_amg_rigid_refresh10_") + (w[2] == '0' ? std::string("gs") : "sor" + std::string(w)),
                 false, amg});
  }
  amg.amg.smoothing_relaxation = 1.5;
  amg.amg.coarse_smoothing_relaxation = 1.0;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_coarse1", false, amg});
  amg.amg.smoothing_relaxation = loom::amg::SaAmgOptions{}.smoothing_relaxation;
  amg.amg.coarse_smoothing_relaxation = 0;
  // Probes of the existing knobs (issue 15): prolongator damping and the strength threshold.
  for (const char* d : {"1.0", "1.6"}) {
    amg.amg.prolongator_damping = std::stod(d);
    v.push_back({std::string("eigen_pcg_sa_amg_rigid_refresh10_damp") + d, false, amg});
  }
  amg.amg.prolongator_damping = loom::amg::SaAmgOptions{}.prolongator_damping;
  for (const char* d : {"0.02", "0.08"}) {
    amg.amg.strength_threshold = std::stod(d);
    v.push_back({std::string("eigen_pcg_sa_amg_rigid_refresh10_strength") + d, false, amg});
  }
  amg.amg.strength_threshold = 0;
  // The defaults before the range rule and the float diagonal inverses (A/B, issue 15):
  // 8 ranges on every threaded level, double diagonal inverses; and each change alone.
  amg.amg.min_part_dofs = 0;
  amg.amg.float_diagonal = false;
  amg.amg.half_transfers = false;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_before", false, amg});
  amg.amg.half_transfers = true;
  amg.amg.float_diagonal = true;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_ranges8", false, amg});
  amg.amg.min_part_dofs = loom::amg::SaAmgOptions{}.min_part_dofs;
  amg.amg.float_diagonal = false;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_doublediag", false, amg});
  amg.amg.float_diagonal = true;
  // Level 0's P and R in float instead of half (A/B of half_transfers, issue 15).
  amg.amg.half_transfers = false;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_floattransfers", false, amg});
  amg.amg.half_transfers = true;
  amg.amg.float_storage = false;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_double", false, amg});
  amg.amg.float_storage = true;
  // The hierarchy's arrays on 4 KiB pages instead of advised 2 MiB ones (A/B of huge_pages).
  amg.amg.huge_pages = false;
  v.push_back({"eigen_pcg_sa_amg_rigid_refresh10_smallpages", false, amg});
  amg.amg.huge_pages = true;
  amg.amg.prolongator_refresh_steps = 1;
  amg.amg.hierarchy_refresh_steps = 10;
  v.push_back({"eigen_pcg_sa_amg_rigid_hierarchy10", false, amg});
  amg.amg.hierarchy_refresh_steps = 1;
  amg.amg.near_null_modes = 3;
  v.push_back({"eigen_pcg_sa_amg_translations", false, amg});
  v.push_back({"eigen_ldlt", true, bj, 128});
  return v;
}

// Puts the variant's solver, wrapped in Timed, into `solver`; returns the wrapper.
Timed* install_solver(std::unique_ptr<loom::LinearSolver>& solver, const SolverVariant& var, loom::EigenPcg*& pcg) {
  std::unique_ptr<loom::LinearSolver> inner;
  pcg = nullptr;
  if (var.ldlt) {
    inner = std::make_unique<loom::EigenLdlt>();
  } else {
    auto p = std::make_unique<loom::EigenPcg>(var.pcg);
    pcg = p.get();
    inner = std::move(p);
  }
  auto timed = std::make_unique<Timed>(std::move(inner));
  Timed* t = timed.get();
  t->extrapolate = var.extrapolate;
  t->measure_saved = var.measure_saved;
  solver = std::move(timed);
  return t;
}

// The timed steps and the counters, shared by the hang and the drape.
void time_steps(benchmark::State& st, int n, Timed* t, loom::EigenPcg* pcg, const std::function<double()>& step);

// Wool hang with one solver: `warmup` steps from rest, then timed steps.
void BM_WoolSolver(benchmark::State& st, SolverVariant var, int n, int warmup) {
  auto sc = wool_scene(n, var.ldlt);
  loom::EigenPcg* pcg = nullptr;
  Timed* t = install_solver(sc->solver, var, pcg);
  loom::BaraffWitkinOptions o;
  o.kang_cho_damping = 0.01;
  o.warm_start = var.warm_start;
  loom::BaraffWitkin bw(o);
  const double h = 0.01;
  bw.prepare(*sc, h);
  for (int k = 0; k < warmup; ++k) bw.step(*sc, h);
  time_steps(st, n, t, pcg, [&] {
    bw.step(*sc, h);
    return bw.last_step().assemble_seconds;
  });
}

// Wool drape: a 1 m x 1 m wool cloth (gnatv, materials/wool.yaml) released flat in contact with
// the top of a ball (radius 0.3 m, friction 0.5/0.4, as scenes/draped_ball_gnatv_bw.yaml but
// not spinning, no self-collision), h = 2 ms, Kang-Cho c_d = 0.001, through the plugin loader
// as the CLI builds it: the contacts are filter constraints (S changes from step to step as
// the cloth wraps the ball). The variant's solver replaces the scene's after the build.
void BM_DrapeSolver(benchmark::State& st, SolverVariant var, int n, int warmup) {
  loom::Registry registry;
  loom::PluginLoader loader{registry};
  const std::string yaml =
      "mesh: {grid: {nx: " + std::to_string(n) + ", ny: " + std::to_string(n) +
      ", width: 1.0, height: 1.0, plane: xz}}\n"
      "material: {type: gnatv, material_file: " + std::string(LOOM_SOURCE_DIR) + "/materials/wool.yaml}\n"
      "integrator: {type: baraff_witkin, dt: 2.0e-3, kang_cho_damping: 0.001, warm_start: " +
      (var.warm_start ? "true" : "false") + "}\n"
      "solver: {type: eigen_ldlt}\n"
      "colliders: [{type: sphere, center: [0.5, -0.3005, -0.5], radius: 0.3, thickness: 0.001, "
      "friction: {static: 0.5, kinetic: 0.4}}]\n"
      "gravity: [0, -9.81, 0]\n";
  auto sim = loom::Simulation::from_string(yaml, "<bench drape>", ".", {}, loader);
  loom::EigenPcg* pcg = nullptr;
  Timed* t = install_solver(sim->scene().solver, var, pcg);
  for (int k = 0; k < warmup; ++k) sim->step();
  time_steps(st, n, t, pcg, [&] {
    sim->step();
    return 0.0;  // the assembly share is not exposed through Simulation
  });
}

// Bytes one PCG iteration with the sa_amg V-cycle reads and writes, by a count over the
// hierarchy (NUMERICS.md 3.6): matrix blocks with their column index per pass, the diagonal
// inverses, P and R, the dense coarsest factor, and the vectors, each once per kernel that
// streams it. Level passes: the fused first sweep reads a clean row once, another interior
// row 1.5 times (the lower part, then the whole row) and a boundary row twice; the backward
// sweep once. Counter `mb_per_iter`; `gb_per_s` divides it by the CPU time per iteration.
double model_bytes_per_iteration(const loom::EigenPcg& pcg) {
  const loom::amg::SaAmg* amg = const_cast<loom::EigenPcg&>(pcg).amg();
  if (!amg) return 0;
  const auto& lv = amg->levels();
  const double vb = amg->options().float_storage ? 4.0 : 8.0;
  const double db = amg->options().float_storage && amg->options().float_diagonal ? 4.0 : 8.0;
  const double n0 = static_cast<double>(lv[0].rows);
  double bytes = static_cast<double>(lv[0].nnz_blocks) * (72 + 4) + 4 * n0;  // the PCG's double SpMV
  bytes += 17 * 24 * n0;  // SpMV c, q; update x, c, r, q (+x, r written); xpby s, c (+c); filter s, s; dot r, s
  for (std::size_t l = 0; l < lv.size(); ++l) {
    const auto& L = lv[l];
    const double rows = static_cast<double>(L.rows), b = L.block;
    const double dofs = rows * b;
    if (l + 1 == lv.size()) {
      bytes += dofs * dofs * 8 + 3 * dofs * 8;  // two triangular solves on the dense factor
      break;
    }
    const double row_bytes = static_cast<double>(L.nnz_blocks) / rows * (b * b * vb + 4) + 4;
    const double clean = static_cast<double>(L.clean_rows), bnd = static_cast<double>(L.boundary_rows);
    const double interior_other = rows - clean - bnd;
    bytes += row_bytes * (clean + 1.5 * interior_other + 2 * bnd);  // fused forward sweep + residual
    bytes += row_bytes * rows;                                     // backward sweep
    bytes += 2 * rows * b * b * db;                                // diagonal inverses, both sweeps
    const double m = lv[l + 1].block;
    const double tb = l == 0 && amg->options().float_storage && amg->options().half_transfers && b == 3 && m == 6 ? 2.0 : vb;
    bytes += 2 * (static_cast<double>(L.p_nnz_blocks) * (b * m * tb + 4) + 4 * rows);  // R, P
    bytes += 10 * dofs * 8;  // b, x, r in the sweeps, r in R r, x in x += P xc
  }
  return bytes;
}

void time_steps(benchmark::State& st, int n, Timed* t, loom::EigenPcg* pcg, const std::function<double()>& step) {
  t->reset_counts();
  // Heap allocations in the timed steps, when the run preloads a malloc counter exporting
  // `loom_probe_mallocs` (bench/baraff_witkin/malloc_count.c, with the command).
  using Count = unsigned long long (*)();
  const auto mallocs = reinterpret_cast<Count>(dlsym(RTLD_DEFAULT, "loom_probe_mallocs"));
  const unsigned long long m_start = mallocs ? mallocs() : 0;
  const loom::amg::SaAmgTimings t_start = pcg && pcg->amg() ? pcg->amg()->timings() : loom::amg::SaAmgTimings{};
  const int builds_start = pcg && pcg->amg() ? pcg->amg()->prolongator_builds() : 0;
  double step_s = 0, assemble = 0;
  long steps = 0;
  for (auto _ : st) {
    const auto t0 = std::chrono::steady_clock::now();
    const double untimed0 = t->untimed;
    assemble += step();
    step_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() - (t->untimed - untimed0);
    ++steps;
  }
  if (t->measure_saved)
    st.counters["iters_saved"] = static_cast<double>(t->cold_iterations - t->iterations) / std::max(1L, t->solves);
  if (mallocs) st.counters["mallocs_per_step"] = static_cast<double>(mallocs() - m_start) / std::max(1L, steps);
  st.counters["vertices"] = n * n;
  st.counters["setup_ms"] = 1e3 * t->setup;
  st.counters["factorize_ms"] = 1e3 * t->factorize_total / std::max(1L, t->solves);
  st.counters["solve_ms"] = 1e3 * t->solve_total / std::max(1L, t->solves);
  if (assemble > 0) st.counters["assemble_ms"] = 1e3 * assemble / steps;
  st.counters["step_ms"] = 1e3 * step_s / steps;
  st.counters["iters"] = static_cast<double>(t->iterations) / std::max(1L, t->solves);
  if (pcg && pcg->amg()) {
    st.counters["levels"] = static_cast<double>(pcg->amg()->levels().size());
    st.counters["op_complexity"] = pcg->amg()->operator_complexity();
    // Where the multigrid's time goes, ms per step: set-up (of which Galerkin products and
    // prolongator), V-cycles (level-0 smoothing, level-0 residual + transfers, coarser levels).
    const loom::amg::SaAmgTimings& e = pcg->amg()->timings();
    const double per = 1e3 / static_cast<double>(steps);
    st.counters["amg_setup_ms"] = per * (e.setup - t_start.setup);
    st.counters["amg_galerkin_ms"] = per * (e.setup_galerkin - t_start.setup_galerkin);
    st.counters["amg_prolong_ms"] = per * (e.setup_prolongator - t_start.setup_prolongator);
    // The prolongator is rebuilt every k-th step (prolongator_refresh_steps), and at 128^2 and
    // up the few timed steps may hold none of those rebuilds. `amg_prolong_build_ms` is the
    // mean time of one rebuild over every rebuild of the run (the set-up's and the warm-up's
    // included), and `step_ms_amortized` replaces the timed steps' own rebuild time by the
    // long-run share, one rebuild per k steps: the step time of a long run on this scene.
    const int builds = pcg->amg()->prolongator_builds();
    const int k = std::max(1, pcg->amg()->options().prolongator_refresh_steps);
    const double per_build = builds > 0 ? 1e3 * e.setup_prolongator / builds : 0;
    st.counters["amg_prolong_build_ms"] = per_build;
    st.counters["amg_prolong_builds_timed"] = builds - builds_start;
    st.counters["step_ms_amortized"] = 1e3 * step_s / steps - per * (e.setup_prolongator - t_start.setup_prolongator) +
                                       per_build / k;
    st.counters["vcycle_ms"] = per * (e.apply - t_start.apply);
    st.counters["l0_smooth_ms"] = per * (e.apply_fine_smooth - t_start.apply_fine_smooth);
    st.counters["l0_transfer_ms"] = per * (e.apply_fine_transfer - t_start.apply_fine_transfer);
    st.counters["coarse_ms"] = per * (e.apply_coarse - t_start.apply_coarse);
    const auto& lv = pcg->amg()->levels();
    st.counters["l0_blocks_per_row"] = static_cast<double>(lv[0].nnz_blocks) / lv[0].rows;
    st.counters["l0_p_blocks_per_row"] = static_cast<double>(lv[0].p_nnz_blocks) / lv[0].rows;
    st.counters["l0_boundary_frac"] = static_cast<double>(lv[0].boundary_rows) / lv[0].rows;
    st.counters["l0_clean_frac"] = static_cast<double>(lv[0].clean_rows) / lv[0].rows;
    st.counters["mb_per_iter"] = 1e-6 * model_bytes_per_iteration(*pcg);
    st.counters["half_p_rel_err"] = pcg->amg()->half_transfer_error();
    if (lv.size() > 1) {
      st.counters["l1_rows"] = static_cast<double>(lv[1].rows);
      st.counters["l1_blocks_per_row"] = static_cast<double>(lv[1].nnz_blocks) / lv[1].rows;
      st.counters["l1_boundary_frac"] = static_cast<double>(lv[1].boundary_rows) / lv[1].rows;
      st.counters["l1_clean_frac"] = static_cast<double>(lv[1].clean_rows) / lv[1].rows;
    }
  }
}

const bool registered_wool_solvers = [] {
  std::vector<int> sizes{32, 64, 128, 256, 512};
  if (const char* env = std::getenv("LOOM_BENCH_SIZES")) {
    sizes.clear();
    std::stringstream ss(env);
    std::string tok;
    while (std::getline(ss, tok, ',')) sizes.push_back(std::stoi(tok));
  }
  for (const char* scene : {"wool", "drape"})
    for (int n : sizes)
      for (const SolverVariant& v : variants()) {
        if (n > v.max_n) continue;
        const bool drape = scene[0] == 'd';
        const int warmup = drape ? (n <= 128 ? 10 : 3) : (n <= 64 ? 10 : n <= 128 ? 5 : 2);
        const int iters = n <= 64 ? 20 : n <= 128 ? 5 : n <= 256 ? 3 : 2;
        benchmark::RegisterBenchmark(("bw_solver/" + std::string(scene) + std::to_string(n) + "/" + v.name).c_str(),
                                     [v, n, warmup, drape](benchmark::State& st) {
                                       if (drape)
                                         BM_DrapeSolver(st, v, n, warmup);
                                       else
                                         BM_WoolSolver(st, v, n, warmup);
                                     })
            ->Unit(benchmark::kMillisecond)
            ->UseRealTime()
            ->Iterations(iters);
      }
  return true;
}();

// sa_amg's huge_pages A/B on the V-cycle alone (issue 15): two wool hangs at n^2, one with
// the hierarchy's arrays advised as 2 MiB pages (the default) and one on 4 KiB pages, each
// stepped twice; then `pairs` V-cycles on each, alternated (huge, small, huge, ...) on the
// same random vector, each timed on its own (third argument 1: the small-page run is built
// and timed first). The minimum and the median of each are robust
// to the other load of a shared machine in a way that a whole step's mean is not; counters
// in ms per V-cycle and small/huge ratios.
void BM_VCyclePages(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  const int pairs = static_cast<int>(st.range(1));
  const bool small_first = st.range(2) != 0;  // the control: the same pair built in the other order
  struct Run {
    std::unique_ptr<loom::Scene> sc;
    std::unique_ptr<loom::BaraffWitkin> bw;
    loom::amg::SaAmg* amg = nullptr;
    std::vector<double> ms;
  };
  Run runs[2];
  for (int k = 0; k < 2; ++k) {
    Run& r = runs[k];
    r.sc = wool_scene(n, false);
    loom::PcgOptions o;
    o.tolerance = 1e-5;
    o.max_iterations = 100000;
    o.preconditioner = loom::PcgPreconditioner::SaAmg;
    o.amg.huge_pages = (k == 0) != small_first;
    auto pcg = std::make_unique<loom::EigenPcg>(o);
    loom::EigenPcg* p = pcg.get();
    r.sc->solver = std::move(pcg);
    loom::BaraffWitkinOptions bo;
    bo.kang_cho_damping = 0.01;
    r.bw = std::make_unique<loom::BaraffWitkin>(bo);
    r.bw->prepare(*r.sc, 0.01);
    for (int s = 0; s < 2; ++s) r.bw->step(*r.sc, 0.01);
    r.amg = p->amg();
  }
  const std::size_t N = 3 * static_cast<std::size_t>(n) * n;
  std::vector<double> rv(N), z(N);
  for (std::size_t k = 0; k < N; ++k) rv[k] = std::sin(0.37 * static_cast<double>(k) + 0.1);
  for (auto _ : st) {
    for (int q = 0; q < pairs; ++q)
      for (Run& r : runs) {
        const auto t0 = std::chrono::steady_clock::now();
        r.amg->apply(rv.data(), z.data());
        r.ms.push_back(1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
        benchmark::DoNotOptimize(z.data());
      }
  }
  if (small_first) std::swap(runs[0].ms, runs[1].ms);  // runs[0]: huge pages
  auto stat = [](std::vector<double> v, bool median) {
    std::sort(v.begin(), v.end());
    return median ? v[v.size() / 2] : v.front();
  };
  st.counters["huge_min_ms"] = stat(runs[0].ms, false);
  st.counters["small_min_ms"] = stat(runs[1].ms, false);
  st.counters["huge_med_ms"] = stat(runs[0].ms, true);
  st.counters["small_med_ms"] = stat(runs[1].ms, true);
  st.counters["small_over_huge_min"] = stat(runs[1].ms, false) / stat(runs[0].ms, false);
  st.counters["small_over_huge_med"] = stat(runs[1].ms, true) / stat(runs[0].ms, true);
}
BENCHMARK(BM_VCyclePages)->Name("bw_vcycle_pages/wool256")->ArgsProduct({{256}, {60}, {0, 1}})->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_VCyclePages)->Name("bw_vcycle_pages/wool512")->ArgsProduct({{512}, {20}, {0, 1}})->Iterations(1)->Unit(benchmark::kSecond);

// What the PCG tolerance costs in accuracy (counters, not timings): the wool hang at n^2 run
// for `steps` steps of h = 0.01 with sa_amg PCG at tolerance 10^-range(1), against the same
// run at tolerance 1e-10 (the solve error) and against a run at h/2 and tolerance 1e-10 (the
// time-discretisation error, sampled at the same time). Counters: rms_solve_err and
// rms_time_err (RMS vertex position difference / cloth width 10 m), their ratio, iterations per
// step at this tolerance.
std::vector<double> wool_positions(int n, double tol, double h, int steps, double* iters) {
  auto sc = wool_scene(n, false);
  loom::PcgOptions o;
  o.tolerance = tol;
  o.preconditioner = loom::PcgPreconditioner::SaAmg;
  o.max_iterations = 100000;
  sc->solver = std::make_unique<loom::EigenPcg>(o);
  loom::BaraffWitkinOptions bo;
  bo.kang_cho_damping = 0.01;
  loom::BaraffWitkin bw(bo);
  bw.prepare(*sc, h);
  long it = 0;
  for (int k = 0; k < steps; ++k) {
    bw.step(*sc, h);
    it += bw.last_step().linear_iterations;
  }
  if (iters) *iters = static_cast<double>(it) / steps;
  return sc->state.x;
}

double rms_diff(const std::vector<double>& a, const std::vector<double>& b, double width) {
  double s = 0;
  for (std::size_t k = 0; k < a.size(); ++k) s += (a[k] - b[k]) * (a[k] - b[k]);
  return std::sqrt(s / static_cast<double>(a.size() / 3)) / width;
}

void BM_ToleranceError(benchmark::State& st) {
  const int n = static_cast<int>(st.range(0));
  const double tol = std::pow(10.0, -static_cast<double>(st.range(1)));
  const int steps = static_cast<int>(st.range(2));
  double iters = 0, e_solve = 0, e_time = 0;
  for (auto _ : st) {
    const std::vector<double> x = wool_positions(n, tol, 0.01, steps, &iters);
    const std::vector<double> ref = wool_positions(n, 1e-10, 0.01, steps, nullptr);
    const std::vector<double> half = wool_positions(n, 1e-10, 0.005, 2 * steps, nullptr);
    e_solve = rms_diff(x, ref, 10.0);
    e_time = rms_diff(ref, half, 10.0);
  }
  st.counters["iters"] = iters;
  st.counters["rms_solve_err"] = e_solve;
  st.counters["rms_time_err"] = e_time;
  st.counters["solve_over_time_err"] = e_solve / e_time;
}

}  // namespace

// args: grid n, -log10(tolerance), steps (of h = 0.01 from rest)
BENCHMARK(BM_ToleranceError)->Name("bw_tolerance_error/wool64")->ArgsProduct({{64}, {3, 4, 5, 6}, {100}})->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_ToleranceError)->Name("bw_tolerance_error/wool128")->ArgsProduct({{128}, {3, 4, 5}, {30}})->Iterations(1)->Unit(benchmark::kSecond);

BENCHMARK(BM_MaterialForcesJacobians)->Name("gnatv_forces_jacobians/wool32")->Arg(32)->Unit(benchmark::kMillisecond);

// args: grid n, solver (0 = eigen_pcg, 1 = eigen_ldlt), warm-up steps
BENCHMARK(BM_BaraffWitkinStep)->Name("bw_step/wool32/eigen_pcg")->Args({32, 0, 20})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BaraffWitkinStep)->Name("bw_step/wool32/eigen_ldlt")->Args({32, 1, 20})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BaraffWitkinStep)->Name("bw_step/wool128/eigen_pcg")->Args({128, 0, 10})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BaraffWitkinStep)->Name("bw_step/wool128/eigen_ldlt")->Args({128, 1, 10})->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BaraffWitkinStep)->Name("bw_step/wool256/eigen_pcg")->Args({256, 0, 3})->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_BaraffWitkinStep)->Name("bw_step/wool256/eigen_ldlt")->Args({256, 1, 2})->Unit(benchmark::kMillisecond)->Iterations(1);

BENCHMARK_MAIN();
