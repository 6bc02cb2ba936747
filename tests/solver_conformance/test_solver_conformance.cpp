// Conformance suite: every solver module the plugin loader finds on the build tree's plugin
// path (loom_solver_*.so, CPU backend) is made through the registry, with each of the
// configurations listed below for it (its preconditioners), and must on the shared test
// systems (tests/cholmod/solver_systems.hpp)
//   * solve the projected system of NUMERICS.md 3.4: agree with a dense LDLT of
//     A~ = S A S + (I - S) (random SPD spring networks with pins, 1- and 2-direction
//     constraints and nonzero prescribed z; hanging cloth with pinned corners; the same cloth
//     with contact constraints), to the stated tolerance: the reported relative residual
//     |S(b - A dv)| / |S(b - A z)| is at most `tolerance` and equals the one computed here
//     (up to the rounding of b - A dv),
//     (I - S) dv = z, and the error against the dense answer is at most 1e-6;
//   * on indefinite systems (compressed springs without the clamp; one with a negative
//     diagonal entry, two with a positive diagonal), either report the
//     failure (factorize() false, or converged = false, with a message) or return an answer
//     whose residual really meets the tolerance; what each solver did is printed.
// A solver module without an entry in the table runs with its defaults and tolerance 1e-5.
// Device solvers (filtered_pcg on backend cuda) are skipped here (no GPU is assumed): the
// same checks run for the device filtered_pcg on Thrust's OpenMP system in
// tests/cuda/test_cuda_pcg.cpp, with the CPU and device iterates compared.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <memory>
#include <ostream>
#include <random>
#include <string>
#include <vector>

#include "loom/linear_solver.hpp"
#include "loom/params.hpp"
#include "loom/registry.hpp"
#include "loom/solver_common.hpp"
#include "solver_systems.hpp"

namespace {

using loom::Index;
namespace ts = loom::testsys;

struct Config {
  std::string solver;
  std::string label;
  std::string params;  // YAML map
  double tolerance;
};

void PrintTo(const Config& c, std::ostream* os) { *os << c.solver << "/" << c.label << " " << c.params; }

// Configurations per solver name: each preconditioner / variant with its stated tolerance.
std::vector<Config> configs_for(const std::string& name) {
  const std::string it = "tolerance: 1.0e-10, max_iterations: 20000";
  if (name == "filtered_pcg" || name == "eigen_pcg")  // eigen_pcg: the deprecated name of filtered_pcg
    return {{name, "block_jacobi", "{preconditioner: block_jacobi, " + it + "}", 1e-10},
            {name, "jacobi", "{preconditioner: jacobi, " + it + "}", 1e-10},
            {name, "sa_amg", "{preconditioner: sa_amg, " + it + ", sa_amg: {coarse_dofs: 24}}", 1e-10},
            {name, "sa_amg_translations",
             "{preconditioner: sa_amg, " + it + ", sa_amg: {coarse_dofs: 24, near_null_space: translations}}", 1e-10}};
  if (name == "eigen_ldlt") return {{name, "default", "{}", 1e-10}};
  if (name == "cholmod") return {{name, "default", "{tolerance: 1.0e-10}", 1e-10}};
  if (name == "petsc")
    return {{name, "bjacobi", "{pc: bjacobi, tolerance: 1.0e-10}", 1e-10},
            {name, "jacobi", "{pc: jacobi, tolerance: 1.0e-10, max_iterations: 20000}", 1e-10},
            {name, "gamg", "{pc: gamg, tolerance: 1.0e-10}", 1e-10},
            {name, "boomeramg", "{pc: boomeramg, tolerance: 1.0e-10}", 1e-10}};
  return {{name, "default", "{}", 1e-5}};
}

loom::Registry& registry() {
  static loom::Registry r;
  return r;
}

loom::PluginLoader& loader() {
  static loom::PluginLoader l(registry(), {std::string(LOOM_BINARY_DIR) + "/lib/loom/plugins"});
  return l;
}

std::vector<Config> all_configs() {
  std::vector<Config> out;
  for (const std::string& name : loader().names(loom::PluginKind::Solver)) {
    try {
      loader().ensure(loom::PluginKind::Solver, name);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "conformance: solver module %s did not load: %s\n", name.c_str(), e.what());
      out.push_back({name, "load_failure", "", 0});
      continue;
    }
    if (!registry().has(loom::PluginKind::Solver, name, "cpu")) continue;  // GPU-only solvers
    for (const Config& c : configs_for(name)) out.push_back(c);
  }
  return out;
}

std::unique_ptr<loom::LinearSolver> make(const Config& c) {
  const loom::Params p = loom::Params::from_string(c.params, "<conformance " + c.solver + ">");
  return registry().make_solver(c.solver, "cpu", p);
}

struct Result {
  bool factorized = false;
  loom::SolveReport rep;
  std::vector<double> dv;
};

Result run(loom::LinearSolver& s, const ts::System& sys) {
  Result r;
  r.dv.assign(3 * sys.n, 0.0);
  s.analyze_pattern(sys.A, sys.S);
  s.set_coordinates(sys.x);
  r.factorized = s.factorize(sys.A, sys.S, r.rep);
  if (r.factorized) r.rep = s.solve(sys.A, sys.S, sys.b, sys.z, r.dv);
  return r;
}

// Independent relative residual |S(b - A dv)| / |S(b - A z)| from the dense matrices.
double dense_residual(const ts::System& s, const std::vector<double>& dv) {
  const Eigen::MatrixXd A = ts::dense(s.A), S = ts::dense_filter(s.S);
  const Eigen::Index N = A.rows();
  const Eigen::Map<const Eigen::VectorXd> b(s.b.data(), N), z(s.z.data(), N), x(dv.data(), N);
  return (S * (b - A * x)).norm() / (S * (b - A * z)).norm();
}

void expect_conforms(const Config& c, const ts::System& sys, const std::string& what) {
  auto solver = make(c);
  const Result r = run(*solver, sys);
  ASSERT_TRUE(r.factorized) << what << ": " << r.rep.message;
  ASSERT_TRUE(r.rep.converged) << what << ": " << r.rep.message;
  const double res = dense_residual(sys, r.dv);
  EXPECT_LE(r.rep.residual, c.tolerance) << what;
  // The two residuals agree up to the rounding of b - A dv (~1e-12 relative here).
  EXPECT_LE(res, 1.1 * c.tolerance) << what;
  EXPECT_NEAR(r.rep.residual, res, 1e-6 * res + 0.1 * c.tolerance) << what;
  EXPECT_LT(ts::rel_diff(r.dv, ts::dense_solution(sys)), c.tolerance <= 1e-10 ? 1e-6 : 1e-2) << what;
  for (Index i : sys.S.constrained()) {
    double sd[3] = {r.dv[3 * i], r.dv[3 * i + 1], r.dv[3 * i + 2]};
    loom::solver::filter_vertex(sys.S, i, sd);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(r.dv[3 * i + a] - sd[a], sys.z[3 * i + a], 1e-12) << what << " vertex " << i;
  }
}

class Conformance : public ::testing::TestWithParam<Config> {};

TEST_P(Conformance, LoadsAndMakes) {
  const Config& c = GetParam();
  ASSERT_NE(c.label, "load_failure") << "the module " << c.solver << " is on the plugin path but does not load";
  auto s = make(c);
  ASSERT_TRUE(s);
  EXPECT_EQ(s->name(), c.solver);
}

TEST_P(Conformance, RandomSpdNetworksWithConstraints) {
  const Config& c = GetParam();
  if (c.label == "load_failure") GTEST_SKIP();
  for (std::uint64_t seed : {1u, 2u, 3u}) {
    const ts::System s = ts::random_network(60 + 40 * static_cast<Index>(seed), seed);
    ASSERT_GT(ts::min_eig_on_range(s), 0.0);
    expect_conforms(c, s, c.solver + "/" + c.label + " random network seed " + std::to_string(seed));
  }
}

TEST_P(Conformance, ClothWithPinsAndContacts) {
  const Config& c = GetParam();
  if (c.label == "load_failure") GTEST_SKIP();
  expect_conforms(c, ts::cloth(12), c.solver + "/" + c.label + " hanging cloth 12^2");
  ts::System s = ts::cloth(14, 1e-3, 1e4, 3);
  std::mt19937_64 rng(7);
  ts::random_constraints(s, rng, 0.03, 0.1, 0.05, true);  // pins plus 1- and 2-direction contacts
  expect_conforms(c, s, c.solver + "/" + c.label + " cloth 14^2 with contacts");
}

TEST_P(Conformance, IndefiniteSystemIsReportedOrSolved) {
  const Config& c = GetParam();
  if (c.label == "load_failure") GTEST_SKIP();
  const ts::System s = ts::random_network(90, 17, 0.05, 0.6, 3, false);
  ASSERT_LT(ts::min_eig_on_range(s), 0.0);
  auto solver = make(c);
  const Result r = run(*solver, s);
  if (!r.factorized || !r.rep.converged) {
    EXPECT_FALSE(r.rep.message.empty()) << "a failure must say why";
    std::printf("conformance: %s/%s on an indefinite system: reported (%s)\n", c.solver.c_str(), c.label.c_str(),
                r.rep.message.substr(0, 160).c_str());
  } else {
    const double res = dense_residual(s, r.dv);
    EXPECT_LE(res, 1.1 * c.tolerance) << "converged = true must mean the residual is met";
    std::printf("conformance: %s/%s on an indefinite system: solved anyway (residual %.3g; not a definiteness test)\n",
                c.solver.c_str(), c.label.c_str(), res);
  }
}

// Indefinite on range(S) with a positive diagonal (strongly compressed springs, no clamp, a
// larger step; found by the same search as tests/cholmod): the diagonal checks pass, so
// the factorisation, the Krylov curvature or the true residual must decide.
TEST_P(Conformance, IndefiniteWithPositiveDiagonalIsReportedOrSolved) {
  const Config& c = GetParam();
  if (c.label == "load_failure") GTEST_SKIP();
  int checked = 0;
  for (int t = 0; t < 60 && checked < 2; ++t) {
    const ts::System s = ts::random_network(40, 100 + t, 0.005 * (1 + t % 6), 0.6, 3, false);
    if (ts::min_eig_on_range(s) > -1e-3 || ts::projected_matrix(s).diagonal().minCoeff() <= 0.0) continue;
    ++checked;
    auto solver = make(c);
    const Result r = run(*solver, s);
    if (!r.factorized || !r.rep.converged) {
      EXPECT_FALSE(r.rep.message.empty()) << "a failure must say why";
      std::printf("conformance: %s/%s, indefinite system %d (positive diagonal): reported (%s)\n", c.solver.c_str(),
                  c.label.c_str(), t, r.rep.message.substr(0, 120).c_str());
    } else {
      const double res = dense_residual(s, r.dv);
      EXPECT_LE(res, 1.1 * c.tolerance) << "converged = true must mean the residual is met";
      std::printf("conformance: %s/%s, indefinite system %d (positive diagonal): solved (residual %.3g)\n",
                  c.solver.c_str(), c.label.c_str(), t, res);
    }
  }
  EXPECT_EQ(checked, 2);
}

std::string config_name(const ::testing::TestParamInfo<Config>& info) {
  return info.param.solver + "_" + info.param.label;
}

INSTANTIATE_TEST_SUITE_P(EverySolver, Conformance, ::testing::ValuesIn(all_configs()), config_name);

// The suite must have found the solvers this build always has.
TEST(ConformanceSuite, FindsTheBuiltSolvers) {
  const auto names = loader().names(loom::PluginKind::Solver);
  for (const char* expected : {"filtered_pcg", "eigen_pcg", "eigen_ldlt"})
    EXPECT_NE(std::find(names.begin(), names.end(), expected), names.end()) << expected;
}

}  // namespace
