// The filtered PCG's SpMV from the upper triangle (plugins/solvers/eigen/upper_spmv.hpp): on
// symmetric matrices it equals the full row product to rounding and the PCG reaches the same
// answer in the same iterations; a matrix whose triangles disagree, or a pattern that is not
// structurally symmetric, falls back to the full rows (and still solves correctly).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <vector>

#include "eigen_pcg.hpp"
#include "loom/solver_common.hpp"
#include "solver_systems.hpp"
#include "upper_spmv.hpp"

namespace {

using loom::Index;
namespace ts = loom::testsys;

std::vector<ts::System> systems() { return ts::preconditioner_systems(); }

loom::SolveReport solve(ts::System& s, loom::PcgOptions o, std::vector<double>& dv, bool& upper_used) {
  loom::EigenPcg p(o);
  p.set_coordinates(s.x);
  p.analyze_pattern(s.A, s.S);
  loom::SolveReport f;
  EXPECT_TRUE(p.factorize(s.A, s.S, f)) << f.message;
  dv.assign(3 * static_cast<std::size_t>(s.n), 0.0);
  loom::SolveReport r = p.solve(s.A, s.S, s.b, s.z, dv);
  upper_used = p.upper_triangle_in_use();
  return r;
}

}  // namespace

// Every row of the product equals the full row product (Eigen's dense A x) to rounding.
TEST(UpperTriangleSpmv, EqualsTheFullProductOnSymmetricMatrices) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> g;
  for (ts::System& s : systems()) {
    loom::UpperTriangleSpmv u;
    ASSERT_TRUE(u.analyze(s.A.pattern()));
    ASSERT_TRUE(u.symmetric_values(s.A, 1e-12, false));
    const std::size_t N = 3 * static_cast<std::size_t>(s.n);
    std::vector<double> x(N), y(N);
    for (double& e : x) e = g(rng);
    for (Index i = 0; i < s.n; ++i) u.row(s.A, x.data(), i, y.data() + 3 * static_cast<std::size_t>(i));
    const Eigen::VectorXd ref = ts::dense(s.A) * Eigen::Map<const Eigen::VectorXd>(x.data(), static_cast<Eigen::Index>(N));
    const double err = (Eigen::Map<const Eigen::VectorXd>(y.data(), static_cast<Eigen::Index>(N)) - ref).norm();
    EXPECT_LT(err, 1e-14 * ref.norm() * std::sqrt(static_cast<double>(N))) << "n " << s.n;
  }
}

// The PCG (block Jacobi and sa_amg) with the upper-triangle SpMV reaches the dense projected
// solution, and the same answer and iteration count as with the full rows.
TEST(UpperTriangleSpmv, PcgGivesTheSameAnswerAsTheFullRows) {
  for (ts::System& s : systems()) {
    for (auto pc : {loom::PcgPreconditioner::BlockJacobi, loom::PcgPreconditioner::SaAmg}) {
      loom::PcgOptions o;
      o.preconditioner = pc;
      o.tolerance = 1e-10;
      o.amg.coarse_dofs = 24;
      o.upper_triangle_spmv = true;
      std::vector<double> a, b;
      bool ua = false, ub = true;
      const loom::SolveReport ra = solve(s, o, a, ua);
      o.upper_triangle_spmv = false;
      const loom::SolveReport rb = solve(s, o, b, ub);
      ASSERT_TRUE(ra.converged && rb.converged) << ra.message << rb.message;
      EXPECT_TRUE(ua);
      EXPECT_FALSE(ub);
      EXPECT_LE(std::abs(ra.iterations - rb.iterations), 1) << "n " << s.n;
      EXPECT_LT(ts::rel_diff(a, ts::dense_solution(s)), 1e-7) << "n " << s.n;
      EXPECT_LT(ts::rel_diff(a, Eigen::Map<const Eigen::VectorXd>(b.data(), static_cast<Eigen::Index>(b.size()))), 1e-8);
    }
  }
}

// One entry below the diagonal changed by 1e-6 of the largest entry: the values are no longer
// symmetric, the PCG must use the full rows (the upper triangle would be a different matrix).
TEST(UpperTriangleSpmv, AsymmetricValuesFallBackToFullRows) {
  ts::System s = ts::cloth(12);
  const loom::BsrPattern& P = s.A.pattern();
  double big = 0;
  for (double v : s.A.values()) big = std::max(big, std::abs(v));
  Index row = -1;
  for (Index i = 0; i < s.n && row < 0; ++i)
    if (P.diag[i] > P.row_ptr[i]) row = i;
  ASSERT_GE(row, 0);
  s.A.block(P.row_ptr[row])[1] += 1e-6 * big;  // block (row, j < row), entry (0, 1)
  loom::UpperTriangleSpmv u;
  ASSERT_TRUE(u.analyze(P));
  EXPECT_FALSE(u.symmetric_values(s.A, 1e-12, false));
  loom::PcgOptions o;
  o.tolerance = 1e-10;
  o.upper_triangle_spmv = true;
  std::vector<double> dv;
  bool used = true;
  const loom::SolveReport r = solve(s, o, dv, used);
  EXPECT_FALSE(used);
  ASSERT_TRUE(r.converged) << r.message;
  EXPECT_LE(r.residual, 1e-10);  // the true residual, on the full (perturbed) matrix
}

// A pattern with (0, 1) but not (1, 0) is not structurally symmetric: analyze() refuses it.
TEST(UpperTriangleSpmv, RefusesAStructurallyAsymmetricPattern) {
  loom::BsrPattern P;
  P.n = 2;
  P.row_ptr = {0, 2, 3};
  P.col = {0, 1, 1};
  P.diag = {0, 2};
  loom::UpperTriangleSpmv u;
  EXPECT_FALSE(u.analyze(P));
  P.row_ptr = {0, 2, 4};
  P.col = {0, 1, 0, 1};
  P.diag = {0, 3};
  EXPECT_TRUE(u.analyze(P));
}
