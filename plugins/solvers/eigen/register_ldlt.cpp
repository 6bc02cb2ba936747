#include <loom/plugin.hpp>

#include <memory>

#include "eigen_ldlt.hpp"

static void register_eigen_ldlt(loom::Registry& r) {
  r.add_solver({loom::PluginKind::Solver, "eigen_ldlt", "cpu", "1.0",
                "Eigen SimplicialLDLT of the projected system S A S + (I - S)", "", &loom::ldlt_spec()},
               [](const loom::Params& p) { return std::make_unique<loom::EigenLdlt>(loom::parse_ldlt_options(p)); });
}

LOOM_PLUGIN(register_eigen_ldlt)
