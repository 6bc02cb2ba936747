#include <loom/plugin.hpp>

#include "cholmod_solver.hpp"

static void register_cholmod(loom::Registry& r) {
  r.add_solver({loom::PluginKind::Solver, "cholmod", "cpu", "1.0",
                "SuiteSparse CHOLMOD supernodal Cholesky of the projected system (OpenBLAS)", "",
                &loom::CholmodOptions::spec()},
               [](const loom::Params& p) { return std::make_unique<loom::CholmodSolver>(p); });
}

LOOM_PLUGIN(register_cholmod)
