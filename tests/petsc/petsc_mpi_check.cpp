// Run under `mpirun -n 2`: solves the same systems with the `petsc` solver distributed over
// MPI_COMM_WORLD and serially (MPI_COMM_SELF) on every rank, and compares both with each
// other and with a dense LDLT reference. Exit code 0 only when everything agrees;
// --inject-error perturbs the distributed answer on the last rank (negative control).
#include <mpi.h>

#include <cstdio>
#include <cstring>
#include <string>

#include "loom/params.hpp"
#include "loom/registry.hpp"
#include "petsc_solver.hpp"
#include "solver_systems.hpp"

using namespace loom;

namespace {

int failures = 0;
int rank = 0, size = 1;

void check(bool ok, const std::string& what) {
  if (!ok) {
    ++failures;
    std::printf("[rank %d] FAILED: %s\n", rank, what.c_str());
  }
}

double max_over_ranks(double v) {
  double g = v;
  MPI_Allreduce(&v, &g, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
  return g;
}

std::vector<double> run(LinearSolver& solver, const testsys::System& s, SolveReport& rep) {
  solver.analyze_pattern(s.A, s.S);
  SolveReport f;
  check(solver.factorize(s.A, s.S, f), "factorize: " + f.message);
  std::vector<double> dv(3 * s.n, 0.0);
  rep = solver.solve(s.A, s.S, s.b, s.z, dv);
  check(rep.converged, solver.name() + " did not converge: " + rep.message);
  return dv;
}

void compare(const char* label, const testsys::System& s, LinearSolver& dist, bool inject) {
  PetscSolverOptions so;
  so.tolerance = 1e-12;
  if (auto* p = dynamic_cast<PetscSolver*>(&dist)) so.pc = p->pc_type();
  SolveReport rd, rs;
  std::vector<double> d = run(dist, s, rd);
  PetscSolver serial(so, MPI_COMM_SELF);
  std::vector<double> ser = run(serial, s, rs);
  if (inject && rank == size - 1) d[3 * s.n / 2] += 1e-6 * (1.0 + std::abs(d[3 * s.n / 2]));

  double num = 0, den = 0;
  for (std::size_t i = 0; i < d.size(); ++i) {
    num += (d[i] - ser[i]) * (d[i] - ser[i]);
    den += ser[i] * ser[i];
  }
  const double diff = max_over_ranks(std::sqrt(num / den));
  const double ref = max_over_ranks(testsys::rel_diff(d, testsys::dense_solution(s)));
  // Every rank must hold the same full solution.
  std::vector<double> d0(d);
  MPI_Bcast(d0.data(), static_cast<int>(d0.size()), MPI_DOUBLE, 0, MPI_COMM_WORLD);
  double spread = 0;
  for (std::size_t i = 0; i < d.size(); ++i) spread = std::max(spread, std::abs(d[i] - d0[i]));
  spread = max_over_ranks(spread);
  if (rank == 0)
    std::printf("%-28s n=%5d  ranks=%d  iterations dist/serial %3d/%3d  |dist-serial|/|serial| %.2e  "
                "vs dense %.2e  rank spread %.1e\n",
                label, s.n, size, rd.iterations, rs.iterations, diff, ref, spread);
  if (diff > 1e-8 || spread > 0.0) {
    ++failures;
    if (rank == 0) std::printf("FAILED: distributed and serial solutions differ by %.3e (rank spread %.3e)\n", diff, spread);
  }
  check(ref < 1e-8, std::string(label) + ": distributed solution differs from the dense reference");
}

}  // namespace

int main(int argc, char** argv) {
  int expect = 0;
  bool inject = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--expect-ranks") && i + 1 < argc) expect = std::atoi(argv[++i]);
    if (!std::strcmp(argv[i], "--inject-error")) inject = true;
  }
  try {
    // First solver from the real module (loaded RTLD_LOCAL, as `loom` does): PETSc and MPI
    // start from inside the plugin.
    Registry registry;
    PluginLoader loader(registry, {std::string(LOOM_BINARY_DIR) + "/lib/loom/plugins"});
    loader.ensure(PluginKind::Solver, "petsc");
    auto module_solver = registry.make_solver("petsc", "cpu", Params::from_string("pc: bjacobi\ntolerance: 1.0e-12\n"));
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &size);
    if (expect > 0 && size != expect) {
      std::printf("FAILED: expected %d ranks, got %d (not started by mpirun?)\n", expect, size);
      return 1;
    }
    testsys::System net = testsys::random_network(300, 42);
    compare("module, bjacobi, network", net, *module_solver, inject);

    testsys::System cloth = testsys::cloth(20, 1e-3, 1e3);
    for (const char* pc : {"jacobi", "bjacobi", "gamg"}) {
      PetscSolverOptions o;
      o.pc = pc;
      o.tolerance = 1e-12;
      PetscSolver dist(o, MPI_COMM_WORLD);
      if (size > 1) check(dist.row_end() - dist.row_begin() < cloth.n, "rows are not distributed");
      compare((std::string(pc) + ", cloth 20x20").c_str(), cloth, dist, inject);
    }
  } catch (const std::exception& e) {
    std::printf("[rank %d] FAILED: exception: %s\n", rank, e.what());
    return 1;
  }
  int total = 0;
  MPI_Allreduce(&failures, &total, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD);
  if (rank == 0) std::printf("%s\n", total == 0 ? "petsc_mpi_check: OK" : "petsc_mpi_check: FAILED");
  return total == 0 ? 0 : 1;
}
