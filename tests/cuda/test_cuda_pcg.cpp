// One filtered PCG for every backend (issue 15): the CPU plugin filtered_pcg (OpenMP loops) and
// the CUDA plugin filtered_pcg (device vectors; here Thrust's OpenMP system, on a GPU in
// test_cuda_gpu) instantiate the same loop (loom/filtered_pcg.hpp). On the same system they
// must produce the same iterates up to rounding (the only difference is the order of the
// reductions and of the SpMV sums), and the device solver must pass the solver conformance
// checks of tests/solver_conformance (dense projected answer, stated tolerance on the true
// relative residual, (I - S) dv = z).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "device_pcg.hpp"
#include "eigen_pcg.hpp"
#include "loom/filtered_pcg.hpp"
#include "loom/solver_common.hpp"
#include "solver_systems.hpp"

using namespace loom;
namespace lc = loom::cuda;
namespace ts = loom::testsys;

namespace {

double rel(const std::vector<double>& a, const std::vector<double>& b) {
  double d = 0, n = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    d += (a[k] - b[k]) * (a[k] - b[k]);
    n += b[k] * b[k];
  }
  return std::sqrt(d / n);
}

ts::System system_with_contacts() {
  ts::System s = ts::cloth(10, 1e-3, 1e3, 3);
  std::mt19937_64 rng(11);
  ts::random_constraints(s, rng, 0.03, 0.1, 0.05, true);  // pins plus 1- and 2-direction contacts, z != 0
  return s;
}

/// The matrix and the filter of s on the device, rounded to T.
template <class T>
void upload_system(const ts::System& s, lc::DeviceBsr<T>& A, lc::DeviceFilter<T>& S) {
  A.set_pattern(s.A.pattern());
  lc::upload(s.A.values(), A.values);
  S.upload(s.S);
}

struct PcgRun {
  SolveReport rep;
  std::vector<double> dv;
};

/// One solve of `s` by `pcg` from `guess` (zero when empty).
PcgRun solve_from(LinearSolver& pcg, const ts::System& s, std::vector<double> guess) {
  PcgRun r;
  r.dv = guess.empty() ? std::vector<double>(3 * s.n, 0.0) : guess;
  pcg.analyze_pattern(s.A, s.S);
  EXPECT_TRUE(pcg.factorize(s.A, s.S, r.rep)) << r.rep.message;
  r.rep = pcg.solve(s.A, s.S, s.b, s.z, r.dv);
  return r;
}

PcgRun run_cpu(const ts::System& s, PcgPreconditioner pc, double tol, int max_it, std::vector<double> guess = {}) {
  PcgOptions o;
  o.preconditioner = pc;
  o.tolerance = tol;
  o.max_iterations = max_it;
  EigenPcg pcg(o);
  return solve_from(pcg, s, std::move(guess));
}

PcgRun run_dev(const ts::System& s, PcgPreconditioner pc, double tol, int max_it, std::vector<double> guess = {}) {
  lc::PcgOptions o;
  o.preconditioner = pc == PcgPreconditioner::None     ? lc::PcgOptions::Preconditioner::None
                     : pc == PcgPreconditioner::Jacobi ? lc::PcgOptions::Preconditioner::Jacobi
                                                       : lc::PcgOptions::Preconditioner::BlockJacobi;
  o.tolerance = tol;
  o.max_iterations = max_it;
  lc::CusparsePcg pcg(o);
  return solve_from(pcg, s, std::move(guess));
}

}  // namespace

class SameIterates : public ::testing::TestWithParam<PcgPreconditioner> {};

// After k iterations (the cap stops both), dv agrees to rounding: the two backends run the same
// loop. The iterates move by far more than the tolerance between k values, so agreement is not
// an artefact of convergence.
TEST_P(SameIterates, CpuAndDeviceAgreeAfterEachIterationCount) {
  const ts::System s = system_with_contacts();
  std::vector<double> prev;
  for (int k : {1, 2, 3, 5, 8, 13, 21}) {
    const PcgRun c = run_cpu(s, GetParam(), 1e-15, k);
    const PcgRun d = run_dev(s, GetParam(), 1e-15, k);
    ASSERT_EQ(c.rep.iterations, k);
    ASSERT_EQ(d.rep.iterations, k);
    EXPECT_FALSE(c.rep.converged);
    EXPECT_FALSE(d.rep.converged);
    EXPECT_LE(rel(d.dv, c.dv), 1e-12) << "after " << k << " iterations";
    EXPECT_NEAR(d.rep.residual, c.rep.residual, 1e-10 * c.rep.residual) << k;
    if (!prev.empty()) {
      EXPECT_GT(rel(c.dv, prev), 1e-6) << "the iterate moved between " << k << " and before";
    }
    prev = c.dv;
  }
  // And run to convergence: the same iteration count and answer.
  const PcgRun c = run_cpu(s, GetParam(), 1e-10, 5000);
  const PcgRun d = run_dev(s, GetParam(), 1e-10, 5000);
  ASSERT_TRUE(c.rep.converged) << c.rep.message;
  ASSERT_TRUE(d.rep.converged) << d.rep.message;
  EXPECT_LE(std::abs(c.rep.iterations - d.rep.iterations), 1);
  EXPECT_LE(rel(d.dv, c.dv), 1e-9);
}

// A warm start (the previous step's dv) is used the same way by both.
TEST_P(SameIterates, WarmStartIsTheSame) {
  const ts::System s = system_with_contacts();
  const PcgRun first = run_cpu(s, GetParam(), 1e-3, 5000);
  ASSERT_TRUE(first.rep.converged);
  const PcgRun c = run_cpu(s, GetParam(), 1e-15, 4, first.dv);
  const PcgRun d = run_dev(s, GetParam(), 1e-15, 4, first.dv);
  EXPECT_LE(rel(d.dv, c.dv), 1e-12);
  EXPECT_LT(c.rep.residual, 1e-3);  // started from the warm start, not from z
}

INSTANTIATE_TEST_SUITE_P(Preconditioners, SameIterates,
                         ::testing::Values(PcgPreconditioner::BlockJacobi, PcgPreconditioner::Jacobi,
                                           PcgPreconditioner::None));

// The conformance checks of tests/solver_conformance for the device filtered_pcg (that suite
// loads the cpu modules only; the device solver runs here on Thrust's OpenMP system).
TEST(DeviceFilteredPcg, ConformsOnTheSharedSystems) {
  std::vector<ts::System> systems;
  for (std::uint64_t seed : {1u, 2u}) systems.push_back(ts::random_network(60 + 40 * static_cast<Index>(seed), seed));
  systems.push_back(ts::cloth(12));
  systems.push_back(system_with_contacts());
  for (const ts::System& s : systems) {
    const PcgRun d = run_dev(s, PcgPreconditioner::BlockJacobi, 1e-10, 20000);
    ASSERT_TRUE(d.rep.converged) << d.rep.message;
    // The reported residual is the true relative residual, recomputed here from the dense matrices.
    const Eigen::MatrixXd A = ts::dense(s.A), S = ts::dense_filter(s.S);
    const Eigen::Map<const Eigen::VectorXd> b(s.b.data(), A.rows()), z(s.z.data(), A.rows()), x(d.dv.data(), A.rows());
    const double res = (S * (b - A * x)).norm() / (S * (b - A * z)).norm();
    EXPECT_LE(d.rep.residual, 1e-10);
    EXPECT_LE(res, 1.1e-10);
    EXPECT_NEAR(d.rep.residual, res, 1e-6 * res + 1e-11);
    EXPECT_LT(ts::rel_diff(d.dv, ts::dense_solution(s)), 1e-6);
    for (Index i : s.S.constrained()) {
      double sd[3] = {d.dv[3 * i], d.dv[3 * i + 1], d.dv[3 * i + 2]};
      solver::filter_vertex(s.S, i, sd);
      for (int a = 0; a < 3; ++a) EXPECT_NEAR(d.dv[3 * i + a] - sd[a], s.z[3 * i + a], 1e-12);
    }
  }
}

// One stopping rule: the same tolerance means the same thing on both backends (the default
// is the same, and a loose tolerance stops both at the same iteration).
TEST(DeviceFilteredPcg, SameDefaultsAndStoppingRuleAsTheCpu) {
  EXPECT_EQ(lc::PcgOptions{}.tolerance, PcgOptions{}.tolerance);
  EXPECT_EQ(lc::PcgOptions{}.tolerance, pcg::kDefaultTolerance);
  EXPECT_EQ(lc::PcgOptions{}.max_iterations, PcgOptions{}.max_iterations);
  const ts::System s = system_with_contacts();
  for (double tol : {1e-2, 1e-4, 1e-6}) {
    const PcgRun c = run_cpu(s, PcgPreconditioner::BlockJacobi, tol, 5000);
    const PcgRun d = run_dev(s, PcgPreconditioner::BlockJacobi, tol, 5000);
    EXPECT_TRUE(c.rep.converged && d.rep.converged);
    EXPECT_EQ(c.rep.iterations, d.rep.iterations) << tol;
    EXPECT_LE(d.rep.residual, tol);
  }
}

// Mixed precision (precision: float on the device; DevicePcg<double, float>): the matrix and the
// filter in float, the vectors and reductions in double. It is CG in double on the rounded
// system: against the double PCG on fl32(A) and fl32(S) held in double (an independent run of
// the double code), the same iterates to rounding after each iteration count, and it reaches a
// tolerance far below float vectors' floor (FloatRoundingFloorIsReportedWithTheFix).
TEST(DeviceFilteredPcg, MixedPrecisionIsDoubleCgOnTheRoundedSystem) {
  const ts::System s = system_with_contacts();
  lc::DeviceBsr<float> A32;
  lc::DeviceFilter<float> S32;
  upload_system(s, A32, S32);
  // The reference: the rounded values in double.
  std::vector<double> rounded(s.A.values().begin(), s.A.values().end());
  for (double& v : rounded) v = static_cast<double>(static_cast<float>(v));
  lc::DeviceBsr<double> A64;
  A64.set_pattern(s.A.pattern());
  lc::upload(rounded, A64.values);
  lc::DeviceFilter<double> S64;
  S64.upload(s.S);
  std::vector<double> proj(S64.proj.size());
  thrust::copy(S64.proj.begin(), S64.proj.end(), proj.begin());
  bool changed = false;
  for (double& v : proj) {
    const double r = static_cast<double>(static_cast<float>(v));
    changed |= r != v;
    v = r;
  }
  ASSERT_TRUE(changed) << "the test's projectors must need rounding";
  lc::upload(proj, S64.proj);
  lc::DVec<double> b, z;
  lc::upload(s.b, b);
  lc::upload(s.z, z);
  const auto solve = [&](auto& pcg, const auto& A, const auto& S, int cap, double tol) {
    lc::PcgOptions o;
    o.tolerance = tol;
    o.max_iterations = cap;
    pcg = std::remove_reference_t<decltype(pcg)>(o);
    pcg.analyze(s.n);
    SolveReport rep;
    EXPECT_TRUE(pcg.factorize(A, S, rep)) << rep.message;
    lc::DVec<double> dv(s.b.size(), 0.0);
    rep = pcg.solve(A, S, b, z, dv);
    std::vector<double> out(dv.size());
    thrust::copy(dv.begin(), dv.end(), out.begin());
    return std::make_pair(rep, out);
  };
  lc::DevicePcg<double, float> mixed;
  lc::DevicePcg<double> ref;
  std::vector<double> prev;
  for (int k : {1, 2, 3, 5, 8, 13, 21}) {
    const auto m = solve(mixed, A32, S32, k, 1e-15);
    const auto r = solve(ref, A64, S64, k, 1e-15);
    ASSERT_EQ(m.first.iterations, k);
    ASSERT_EQ(r.first.iterations, k);
    EXPECT_LE(rel(m.second, r.second), 1e-12) << "after " << k << " iterations";
    if (!prev.empty()) {
      EXPECT_GT(rel(m.second, prev), 1e-6) << "the iterate moved";
    }
    prev = m.second;
  }
  // To convergence, at 1e-7: below where float vectors stop on this system (7.0e-7, the next
  // test), above where the float filter's rounding ends the filtered CG (between 1e-7 and 1e-8
  // here, for the double run on the rounded system as well: fl32(S) is a projector only to
  // float rounding, so below that the iteration loses the range of S).
  const auto m = solve(mixed, A32, S32, 100000, 1e-7);
  const auto r = solve(ref, A64, S64, 100000, 1e-7);
  EXPECT_TRUE(m.first.converged) << m.first.message;
  EXPECT_LE(m.first.residual, 1e-7);
  EXPECT_LE(std::abs(m.first.iterations - r.first.iterations), 1);
  EXPECT_LE(rel(m.second, r.second), 1e-12);
  std::printf("[ measured ] mixed: %d iterations to %.3g (double on the rounded system: %d)\n", m.first.iterations,
              m.first.residual, r.first.iterations);
}

// The deprecated names still work and keep their name (the plugin prints a one-line note).
TEST(DeviceFilteredPcg, DeprecatedNamesStillWork) {
  EXPECT_EQ(lc::CusparsePcg(Params(), "cusparse_pcg").name(), "cusparse_pcg");
  EXPECT_EQ(lc::CusparsePcg(Params()).name(), "filtered_pcg");
  EXPECT_EQ(EigenPcg(PcgOptions{}, "eigen_pcg").name(), "eigen_pcg");
  EXPECT_EQ(EigenPcg().name(), "filtered_pcg");
  // sa_amg is a cpu preconditioner: the device key table does not offer it.
  EXPECT_THROW(lc::CusparsePcg(Params::from_string("{preconditioner: sa_amg}")), InputError);
}

// Float vectors (precision: float on the device): rounding keeps the true residual above a tight
// tolerance while the recursive one reaches it, and the report says so with the fix, instead
// of "not converged, raise max_iterations". Seen on an H200 (2026-11-30): the float Baraff-
// Witkin wool step stalled at 2.0e-5 (32^2) to 3.8e-3 (512^2) relative against 1e-5.
TEST(DeviceFilteredPcg, FloatRoundingFloorIsReportedWithTheFix) {
  const ts::System s = system_with_contacts();
  lc::DeviceBsr<float> A;
  lc::DeviceFilter<float> S;
  upload_system(s, A, S);
  lc::DVec<float> b, z, dv;
  lc::upload(s.b, b);
  lc::upload(s.z, z);
  dv.assign(s.b.size(), 0.0f);
  lc::PcgOptions o;
  o.tolerance = 1e-11;  // far below float's reach on any system
  o.max_iterations = 100000;
  lc::DevicePcg<float> pcg(o);
  pcg.analyze(s.n);
  SolveReport rep;
  ASSERT_TRUE(pcg.factorize(A, S, rep)) << rep.message;
  rep = pcg.solve(A, S, b, z, dv);
  EXPECT_FALSE(rep.converged);
  EXPECT_GT(rep.residual, 1e-11);
  EXPECT_LT(rep.iterations, 100000) << "stopped by the rule, not by the cap";
  EXPECT_NE(rep.message.find("rounding limits"), std::string::npos) << rep.message;
  EXPECT_NE(rep.message.find("use precision: double"), std::string::npos) << rep.message;
  std::printf("[ measured ] float: %d iterations, relative residual %.3g: %s\n", rep.iterations, rep.residual,
              rep.message.c_str());
  // The same system in double reaches 1e-11.
  const PcgRun d = run_dev(s, PcgPreconditioner::BlockJacobi, 1e-11, 100000);
  EXPECT_TRUE(d.rep.converged) << d.rep.message;
}
