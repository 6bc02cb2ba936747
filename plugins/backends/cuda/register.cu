// loom_backend_cuda: registers the CUDA execution backend's plugins under backend "cuda".
#include <cstdio>
#include <memory>

#include "cuda_integrators.hpp"
#include "device_pcg.hpp"
#include "loom/plugin.hpp"

static void register_cuda(loom::Registry& r) {
  using loom::PluginKind;
  r.add_integrator({PluginKind::Integrator, "harmonic_oscillation", "cuda", "1.0",
                    "harmonic-oscillation spring integration on the GPU (variants velocity, analytic_position, "
                    "kang_cho_2011; precision double | float)", "", &loom::harmonic_oscillation_spec()},
                   [](const loom::Params& p) { return loom::cuda::make_cuda_ho(p); });
  r.add_integrator({PluginKind::Integrator, "rk4", "cuda", "1.0",
                    "classical RK4 on the GPU (precision double | float)", "", &loom::rk4_spec()},
                   [](const loom::Params& p) { return loom::cuda::make_cuda_rk4(p); });
  r.add_integrator({PluginKind::Integrator, "symplectic_euler", "cuda", "1.0",
                    "explicit symplectic Euler on the GPU: device forces, the CPU plugin's vertex update, sphere and "
                    "plane contacts (precision double | float)", "", &loom::symplectic_euler::spec()},
                   [](const loom::Params& p) { return loom::cuda::make_cuda_symplectic_euler(p); });
  r.add_integrator({PluginKind::Integrator, "baraff_witkin", "cuda", "1.0",
                    "Baraff-Witkin implicit step assembled and solved on the GPU (needs solver filtered_pcg)", "",
                    &loom::baraff_witkin_spec()},
                   [](const loom::Params& p) { return loom::cuda::make_cuda_baraff_witkin(p); });
  r.add_solver({PluginKind::Solver, "filtered_pcg", "cuda", "1.0",
                "modified (filtered) PCG on the GPU (the loop of loom/filtered_pcg.hpp): cuSPARSE bsrmv, Thrust "
                "reductions, (block) Jacobi; stops on the true relative residual", "",
                &loom::cuda::filtered_pcg_cuda_spec()},
               [](const loom::Params& p) { return std::make_unique<loom::cuda::CusparsePcg>(p); });
  r.add_solver({PluginKind::Solver, "cusparse_pcg", "cuda", "1.0",
                "deprecated name of filtered_pcg on backend cuda (the same solver and keys)", "",
                &loom::cuda::cusparse_pcg_spec()},
               [](const loom::Params& p) {
                 static bool noted = false;
                 if (!noted)
                   std::fprintf(stderr, "loom: note: solver cusparse_pcg is deprecated, use filtered_pcg (same keys)\n");
                 noted = true;
                 return std::make_unique<loom::cuda::CusparsePcg>(p, "cusparse_pcg");
               });
}

LOOM_PLUGIN(register_cuda)
