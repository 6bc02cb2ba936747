// gnatv assembly benchmarks: force evaluation and Jacobian assembly on n x n wool cloths
// (10 m x 10 m, deformed by a small random displacement), 1 and 2 threads.
//   bench_gnatv --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>
#include <omp.h>

#include <map>
#include <memory>
#include <random>

#include "gnatv_material.hpp"
#include "loom/bsr.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"

namespace {

struct Setup {
  loom::Mesh mesh;
  std::unique_ptr<loom::gnatv::GnatvMaterial> mat;
  loom::BsrPattern pattern;
  std::vector<double> x, v, f;
  explicit Setup(int n) {
    mesh = loom::make_grid(n, n, 10.0, 10.0, loom::GridPlane::XY);
    auto p = loom::Params::from_string(std::string("material_file: ") + LOOM_SOURCE_DIR + "/materials/wool.yaml\n",
                                       "<bench>");
    mat = std::make_unique<loom::gnatv::GnatvMaterial>(p, mesh);
    std::vector<std::array<loom::Index, 2>> pairs;
    mat->jacobian_pairs(pairs);
    pattern = loom::BsrPattern::from_pairs(mesh.num_vertices(), pairs);
    mat->bind_pattern(pattern);
    std::mt19937 rng(1);
    const double h = 10.0 / (n - 1);
    std::uniform_real_distribution<double> U(-0.02 * h, 0.02 * h);
    x = mesh.positions;
    for (double& c : x) c += U(rng);
    v.assign(x.size(), 0.0);
    f.assign(x.size(), 0.0);
  }
};

Setup& setup(int n) {
  static std::map<int, std::unique_ptr<Setup>> cache;
  auto& s = cache[n];
  if (!s) s = std::make_unique<Setup>(n);
  return *s;
}

void BM_Forces(benchmark::State& st) {
  Setup& s = setup(static_cast<int>(st.range(0)));
  omp_set_num_threads(static_cast<int>(st.range(1)));
  for (auto _ : st) {
    s.mat->compute_forces(s.x, s.v, s.f);
    benchmark::DoNotOptimize(s.f.data());
  }
  st.counters["triangles"] = s.mat->num_triangles();
  st.counters["ns_per_tri"] = benchmark::Counter(static_cast<double>(s.mat->num_triangles()),
                                                 benchmark::Counter::kIsIterationInvariantRate |
                                                     benchmark::Counter::kInvert);
}

void BM_Jacobian(benchmark::State& st) {
  Setup& s = setup(static_cast<int>(st.range(0)));
  omp_set_num_threads(static_cast<int>(st.range(1)));
  loom::BsrMatrix J(&s.pattern);
  for (auto _ : st) {
    s.mat->compute_jacobians(s.x, s.v, J, nullptr);
    benchmark::DoNotOptimize(J.values().data());
  }
  st.counters["triangles"] = s.mat->num_triangles();
  st.counters["ns_per_tri"] = benchmark::Counter(static_cast<double>(s.mat->num_triangles()),
                                                 benchmark::Counter::kIsIterationInvariantRate |
                                                     benchmark::Counter::kInvert);
}

}  // namespace

BENCHMARK(BM_Forces)->ArgsProduct({{32, 128, 256}, {1, 2}})->ArgNames({"n", "threads"})->Unit(benchmark::kMicrosecond)->UseRealTime()->MeasureProcessCPUTime();
BENCHMARK(BM_Jacobian)->ArgsProduct({{32, 128, 256}, {1, 2}})->ArgNames({"n", "threads"})->Unit(benchmark::kMicrosecond)->UseRealTime()->MeasureProcessCPUTime();

BENCHMARK_MAIN();
