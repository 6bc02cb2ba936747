#include <loom/plugin.hpp>

#include "petsc_solver.hpp"

static void register_petsc(loom::Registry& r) {
  r.add_solver({loom::PluginKind::Solver, "petsc", "cpu", "1.0",
                "PETSc KSP (CG + Jacobi/block Jacobi/GAMG) on the bs=3 projected system; distributed under mpirun", "",
                &loom::PetscSolverOptions::spec()},
               [](const loom::Params& p) { return std::make_unique<loom::PetscSolver>(p); });
}

LOOM_PLUGIN(register_petsc)
