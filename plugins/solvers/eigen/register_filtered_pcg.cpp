// loom_solver_filtered_pcg: the modified (filtered) PCG of loom/filtered_pcg.hpp on the CPU
// (OpenMP loops over the 3x3 block rows). The CUDA backend registers the same name for the
// device (plugins/backends/cuda/device_pcg.cu), with the same keys and stopping rule.
#include <loom/plugin.hpp>

#include <memory>

#include "eigen_pcg.hpp"

static void register_filtered_pcg(loom::Registry& r) {
  r.add_solver({loom::PluginKind::Solver, "filtered_pcg", "cpu", "1.0",
                "modified (filtered) PCG of Baraff-Witkin on the 3x3 block matrix (stops on the true relative "
                "residual); jacobi, block_jacobi or sa_amg (smoothed-aggregation multigrid)", "",
                &loom::filtered_pcg_spec()},
               [](const loom::Params& p) { return std::make_unique<loom::EigenPcg>(loom::parse_pcg_options(p)); });
}

LOOM_PLUGIN(register_filtered_pcg)
