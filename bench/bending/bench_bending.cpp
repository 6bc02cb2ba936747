// Cost of hinge bending per step against the membrane's (issue 14): force evaluation and
// Jacobian assembly of gnatv (wool, 10 m x 10 m) and of its hinges (B = 1e-3 N m) on n x n
// grids, 1 and 2 threads, the cloth deformed out of plane so that every hinge is bent.
//   build/bin/bench_bending --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
// Per step, Baraff-Witkin evaluates the forces once and the Jacobian once; compare
// Bending* with Membrane* at the same n and threads (ns_per_elem: per hinge / per triangle).
#include <benchmark/benchmark.h>
#include <omp.h>

#include <cmath>
#include <map>
#include <memory>
#include <random>

#include "gnatv_material.hpp"
#include "loom/bending.hpp"
#include "loom/bsr.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"

namespace {

struct Setup {
  loom::Mesh mesh;
  std::unique_ptr<loom::BentMaterial> mat;
  loom::BsrPattern pattern;
  std::vector<double> x, v, f;
  explicit Setup(int n) {
    mesh = loom::make_grid(n, n, 10.0, 10.0, loom::GridPlane::XZ);
    auto p = loom::Params::from_string(std::string("material_file: ") + LOOM_SOURCE_DIR + "/materials/wool.yaml\n",
                                       "<bench>");
    loom::BendingOptions o;
    o.b_weft = o.b_warp = o.b_bias = 1e-3;
    mat = std::make_unique<loom::BentMaterial>(std::make_unique<loom::gnatv::GnatvMaterial>(p, mesh), mesh, o);
    std::vector<std::array<loom::Index, 2>> pairs;
    mat->jacobian_pairs(pairs);  // membrane and hinge pairs: the pattern a scene builds
    pattern = loom::BsrPattern::from_pairs(mesh.num_vertices(), pairs);
    mat->bind_pattern(pattern);
    std::mt19937 rng(1);
    const double h = 10.0 / (n - 1);
    std::uniform_real_distribution<double> U(-0.02 * h, 0.02 * h);
    x = mesh.positions;
    for (std::size_t i = 0; i < x.size(); i += 3) x[i + 1] = 0.3 * std::sin(x[i]) * std::cos(0.7 * x[i + 2]);
    for (double& c : x) c += U(rng);
    v.assign(x.size(), 0.0);
    f.assign(x.size(), 0.0);
  }
  double triangles() const { return mesh.num_triangles(); }
  double hinges() const { return mat->hinges().num_hinges(); }
};

Setup& setup(int n) {
  static std::map<int, std::unique_ptr<Setup>> cache;
  auto& s = cache[n];
  if (!s) s = std::make_unique<Setup>(n);
  return *s;
}

void per_element(benchmark::State& st, double count) {
  st.counters["elements"] = count;
  st.counters["ns_per_elem"] =
      benchmark::Counter(count, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void BM_MembraneForces(benchmark::State& st) {
  Setup& s = setup(static_cast<int>(st.range(0)));
  omp_set_num_threads(static_cast<int>(st.range(1)));
  for (auto _ : st) {
    s.mat->membrane().compute_forces(s.x, s.v, s.f);
    benchmark::DoNotOptimize(s.f.data());
  }
  per_element(st, s.triangles());
}

void BM_BendingForces(benchmark::State& st) {
  Setup& s = setup(static_cast<int>(st.range(0)));
  omp_set_num_threads(static_cast<int>(st.range(1)));
  for (auto _ : st) {
    s.mat->hinges().add_forces(s.x, s.f);
    benchmark::DoNotOptimize(s.f.data());
  }
  per_element(st, s.hinges());
}

void BM_MembraneJacobian(benchmark::State& st) {
  Setup& s = setup(static_cast<int>(st.range(0)));
  omp_set_num_threads(static_cast<int>(st.range(1)));
  loom::BsrMatrix J(&s.pattern);
  for (auto _ : st) {
    s.mat->membrane().compute_jacobians(s.x, s.v, J, nullptr);
    benchmark::DoNotOptimize(J.values().data());
  }
  per_element(st, s.triangles());
}

void bending_jacobian(benchmark::State& st, bool exact) {
  Setup& s = setup(static_cast<int>(st.range(0)));
  omp_set_num_threads(static_cast<int>(st.range(1)));
  s.mat->hinges().set_exact_jacobian(exact);
  loom::BsrMatrix J(&s.pattern);
  for (auto _ : st) {
    s.mat->hinges().add_jacobian(s.x, J);
    benchmark::DoNotOptimize(J.values().data());
  }
  s.mat->hinges().set_exact_jacobian(false);
  per_element(st, s.hinges());
}
void BM_BendingJacobianGaussNewton(benchmark::State& st) { bending_jacobian(st, false); }
void BM_BendingJacobianExact(benchmark::State& st) { bending_jacobian(st, true); }

}  // namespace

#define LOOM_BENCH_ARGS ArgsProduct({{128, 256}, {1, 2}})->ArgNames({"n", "threads"})->Unit(benchmark::kMicrosecond)->UseRealTime()->MeasureProcessCPUTime()
BENCHMARK(BM_MembraneForces)->LOOM_BENCH_ARGS;
BENCHMARK(BM_BendingForces)->LOOM_BENCH_ARGS;
BENCHMARK(BM_MembraneJacobian)->LOOM_BENCH_ARGS;
BENCHMARK(BM_BendingJacobianGaussNewton)->LOOM_BENCH_ARGS;
BENCHMARK(BM_BendingJacobianExact)->LOOM_BENCH_ARGS;
BENCHMARK_MAIN();
