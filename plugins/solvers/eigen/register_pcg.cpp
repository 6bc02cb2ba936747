#include <loom/plugin.hpp>

#include <memory>

#include "eigen_pcg.hpp"

static void register_eigen_pcg(loom::Registry& r) {
  r.add_solver({loom::PluginKind::Solver, "eigen_pcg", "cpu", "1.0",
                "modified (filtered) PCG of Baraff-Witkin on the 3x3 block matrix; jacobi, block_jacobi or sa_amg (smoothed-aggregation multigrid)", "",
                &loom::pcg_spec()},
               [](const loom::Params& p) { return std::make_unique<loom::EigenPcg>(loom::parse_pcg_options(p)); });
}

LOOM_PLUGIN(register_eigen_pcg)
