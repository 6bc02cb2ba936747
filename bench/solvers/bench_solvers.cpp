// Linear-solver backends on the Baraff-Witkin matrix A = M - h^2 K of a hanging mass-spring
// cloth (nx x nx vertices, structural + shear + bend springs, top corners pinned, h^2 k/m =
// 1e3): analysis, factorisation / preconditioner set-up and one cold-start solve, for
// cholmod, petsc (CG + jacobi / bjacobi / gamg / boomeramg, the AMGs with the rigid-body
// near-null space), eigen_ldlt and eigen_pcg (block_jacobi, sa_amg). Every solver gets the
// vertex positions (set_coordinates) before factorize, as Baraff-Witkin gives them.
//
//   bench_solvers --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
//   mpirun -n 2 --oversubscribe bench_solvers --benchmark_filter=petsc ...   (PETSc on 2 ranks;
//       every benchmark runs a fixed number of iterations so that the ranks stay in step;
//       only rank 0 prints)
//   LOOM_BENCH_SIZES=32,64,128,256,512 selects the grids (the default). Skipped at 512^2 (stated
//   so the whole set runs in minutes): eigen_ldlt and cholmod (the fill-in of a 786k-DOF
//   factor: tens of seconds per factorisation on 2 cores) and the one-level preconditioners
//   eigen_pcg (block Jacobi), petsc_jacobi, petsc_bjacobi (thousands of iterations).
#include <benchmark/benchmark.h>
#include <mpi.h>

#include <cstdlib>
#include <functional>
#include <map>
#include <memory>
#include <sstream>
#include <string>

#include "solver_systems.hpp"
#ifdef LOOM_BENCH_CHOLMOD
#include "cholmod_solver.hpp"
#endif
#ifdef LOOM_BENCH_PETSC
#include "petsc_solver.hpp"
#endif
#ifdef LOOM_BENCH_EIGEN
#include "eigen_ldlt.hpp"
#include "eigen_pcg.hpp"
#endif

using namespace loom;

namespace {

constexpr double kIterativeTolerance = 1e-6;  // relative residual for the iterative solvers

testsys::System& cloth(Index nx) {
  static std::map<Index, std::unique_ptr<testsys::System>> cache;
  auto& s = cache[nx];
  if (!s) s = std::make_unique<testsys::System>(testsys::cloth(nx, 1e-3, 1e3));
  return *s;
}

using Factory = std::function<std::unique_ptr<LinearSolver>()>;

enum class Phase { Analyze, Factorize, Solve };

int iterations_for(Index nx) { return nx <= 64 ? 5 : nx <= 128 ? 2 : 1; }

void run(benchmark::State& st, const Factory& make, Index nx, Phase phase) {
  testsys::System& s = cloth(nx);
  auto solver = make();
  std::vector<double> dv(3 * s.n, 0.0);
  SolveReport rep;
  solver->set_coordinates(s.x);
  if (phase != Phase::Analyze) solver->analyze_pattern(s.A, s.S);
  if (phase == Phase::Solve) {
    SolveReport f;
    if (!solver->factorize(s.A, s.S, f)) st.SkipWithError(f.message.c_str());
  }
  for (auto _ : st) {
    switch (phase) {
      case Phase::Analyze:
        solver->analyze_pattern(s.A, s.S);
        break;
      case Phase::Factorize: {
        SolveReport f;
        if (!solver->factorize(s.A, s.S, f)) st.SkipWithError(f.message.c_str());
        break;
      }
      case Phase::Solve:
        std::fill(dv.begin(), dv.end(), 0.0);  // cold start
        rep = solver->solve(s.A, s.S, s.b, s.z, dv);
        if (!rep.converged) st.SkipWithError(rep.message.c_str());
        break;
    }
  }
  st.counters["dofs"] = 3.0 * s.n;
  if (phase == Phase::Solve) {
    st.counters["iters"] = rep.iterations;
    st.counters["residual"] = rep.residual;
    // Bytes of one pass over the BSR matrix (72 B values + 4 B column per block): the
    // traffic floor of one SpMV, for the bandwidth a Krylov iteration achieves.
    const double bytes = 76.0 * s.pattern->nnz_blocks();
    st.counters["matrix_GBps_per_iter"] =
        benchmark::Counter(bytes * rep.iterations * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
  }
#ifdef LOOM_BENCH_CHOLMOD
  if (auto* c = dynamic_cast<CholmodSolver*>(solver.get())) {
    st.counters["nnzL_M"] = c->factor_nnz() * 1e-6;
    st.counters["L_MB"] = c->factor_nnz() * 8e-6;
    if (phase == Phase::Factorize)
      st.counters["GFLOPs"] = benchmark::Counter(c->factor_flops() * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
    st.SetLabel(c->ordering_used());
  }
#endif
#ifdef LOOM_BENCH_PETSC
  if (auto* p = dynamic_cast<PetscSolver*>(solver.get())) {
    st.counters["ranks"] = p->ranks();
    if (phase == Phase::Factorize) {  // split of the last factorize(): assembly vs PC set-up
      st.counters["assemble_ms"] = p->assemble_seconds() * 1e3;
      st.counters["pc_setup_ms"] = p->setup_seconds() * 1e3;
    }
    st.SetLabel(p->matrix_type());
  }
#endif
}

}  // namespace

int main(int argc, char** argv) {
  int rank = 0;
#ifdef LOOM_BENCH_PETSC
  petsc_ensure_initialized();
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
#endif
  std::vector<Index> sizes{32, 64, 128, 256, 512};
  if (const char* env = std::getenv("LOOM_BENCH_SIZES")) {
    sizes.clear();
    std::stringstream ss(env);
    std::string tok;
    while (std::getline(ss, tok, ',')) sizes.push_back(static_cast<Index>(std::stoi(tok)));
  }
  std::vector<std::pair<std::string, Factory>> solvers;
  const auto too_slow_at = [](const std::string& name, Index nx) {
    return nx > 256 && (name == "eigen_ldlt" || name == "cholmod" || name == "eigen_pcg" ||
                        name == "petsc_jacobi" || name == "petsc_bjacobi");
  };
#ifdef LOOM_BENCH_CHOLMOD
  solvers.emplace_back("cholmod", [] { return std::make_unique<CholmodSolver>(); });
#endif
#ifdef LOOM_BENCH_PETSC
  for (const char* pc : {"jacobi", "bjacobi", "gamg", "boomeramg"}) {
    solvers.emplace_back(std::string("petsc_") + pc, [pc] {
      PetscSolverOptions o;
      o.pc = pc;
      o.tolerance = kIterativeTolerance;
      return std::make_unique<PetscSolver>(o);
    });
  }
#endif
#ifdef LOOM_BENCH_EIGEN
  solvers.emplace_back("eigen_ldlt", [] { return std::make_unique<EigenLdlt>(); });
  solvers.emplace_back("eigen_pcg", [] {
    PcgOptions o;
    o.tolerance = kIterativeTolerance;
    o.max_iterations = 100000;
    return std::make_unique<EigenPcg>(o);
  });
  solvers.emplace_back("eigen_pcg_sa_amg", [] {
    PcgOptions o;
    o.tolerance = kIterativeTolerance;
    o.max_iterations = 100000;
    o.preconditioner = PcgPreconditioner::SaAmg;
    return std::make_unique<EigenPcg>(o);
  });
  solvers.emplace_back("eigen_pcg_sa_amg_double", [] {  // the hierarchy stored in double
    PcgOptions o;
    o.tolerance = kIterativeTolerance;
    o.max_iterations = 100000;
    o.preconditioner = PcgPreconditioner::SaAmg;
    o.amg.float_storage = false;
    return std::make_unique<EigenPcg>(o);
  });
#endif
  for (Index nx : sizes)
    for (const auto& [name, make] : solvers) {
      if (too_slow_at(name, nx)) continue;
      for (auto [phase, pname] : {std::pair{Phase::Analyze, "analyze"}, std::pair{Phase::Factorize, "factorize"},
                                  std::pair{Phase::Solve, "solve"}}) {
        const Factory f = make;
        const Phase ph = phase;
        benchmark::RegisterBenchmark((name + "/" + pname + "/" + std::to_string(nx)).c_str(),
                                     [f, nx, ph](benchmark::State& st) { run(st, f, nx, ph); })
            ->Unit(benchmark::kMillisecond)
            ->UseRealTime()
            ->Iterations(iterations_for(nx));
      }
    }
  benchmark::Initialize(&argc, argv);
  if (rank != 0) {  // MPI: only rank 0 reports
    benchmark::BenchmarkReporter* null_reporter = nullptr;
    struct Quiet : benchmark::ConsoleReporter {
      bool ReportContext(const Context&) override { return true; }
      void ReportRuns(const std::vector<Run>&) override {}
    };
    static Quiet quiet;
    null_reporter = &quiet;
    benchmark::RunSpecifiedBenchmarks(null_reporter);
  } else {
    benchmark::RunSpecifiedBenchmarks();
  }
  benchmark::Shutdown();
  return 0;
}
