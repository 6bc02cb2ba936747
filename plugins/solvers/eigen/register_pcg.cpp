// loom_solver_eigen_pcg: the former name of filtered_pcg (register_filtered_pcg.cpp), kept so
// that scenes naming it still run; it prints a one-line deprecation note when made.
#include <loom/plugin.hpp>

#include <cstdio>
#include <memory>

#include "eigen_pcg.hpp"

static void register_eigen_pcg(loom::Registry& r) {
  r.add_solver({loom::PluginKind::Solver, "eigen_pcg", "cpu", "1.0",
                "deprecated name of filtered_pcg (the same solver and keys)", "", &loom::pcg_spec()},
               [](const loom::Params& p) {
                 static bool noted = false;
                 if (!noted)
                   std::fprintf(stderr, "loom: note: solver eigen_pcg is deprecated, use filtered_pcg (same keys)\n");
                 noted = true;
                 return std::make_unique<loom::EigenPcg>(loom::parse_pcg_options(p, loom::pcg_spec()), "eigen_pcg");
               });
}

LOOM_PLUGIN(register_eigen_pcg)
