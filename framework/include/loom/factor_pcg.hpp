// The direct solvers' matrix-free mode for an extra operator E (linear_solver.hpp), option
// `contact_springs: factor_preconditioned_pcg` of eigen_ldlt and cholmod: the solver factors
// the projected A~ = S A S + (I - S) only (A's pattern never grows for E) and solves
// S (A + E) dv = S b, (I - S) dv = z by the filtered PCG (filtered_pcg.hpp, the same start and
// stopping rule as filtered_pcg) with A~'s factor as the preconditioner. E = sum of m rank-one
// terms (self-contact springs) gives A~^-1 (A~ + S E S) at most m eigenvalues other than 1, so
// PCG converges in at most m + 1 iterations in exact arithmetic (docs/CONTACT.md, "Why the
// direct solvers keep the assembled path").
#pragma once

#include <algorithm>
#include <span>
#include <string>

#include "loom/filtered_pcg.hpp"
#include "loom/linear_solver.hpp"
#include "loom/solver_common.hpp"

namespace loom::factor_pcg {

/// The values of the direct solvers' `contact_springs` key.
inline constexpr const char* kAssembled = "assembled";
inline constexpr const char* kFactorPreconditionedPcg = "factor_preconditioned_pcg";

/// Default stopping rule of the mode: the true relative residual of the filtered A + E system.
inline constexpr double kDefaultTolerance = 1e-10;
/// Default iteration cap, well below the rank bound m + 1 of many springs: the folded cloth's 66
/// springs take 10-16 iterations, the draped cloth at 128^2 up to 574 in a step (a cap of 100
/// stopped it). Past it the solve fails with a message naming the key.
inline constexpr int kDefaultMaxIterations = 1000;

/// FilteredPcgOps for A + E with a direct factor as preconditioner. `Factor` is callable as
/// bool(const double* r, double* s): s = A~^-1 r (3n entries).
template <class Factor>
struct Ops {
  using Real = double;
  using Vec = std::span<double>;
  const BsrMatrix& A;
  const Filter& S;
  std::span<const double> b, z;
  const ExtraOperator* E;
  Factor& factor;
  bool factor_ok = true;

  Index n() const { return A.rows(); }
  double residual(const Vec& x, Vec& out) const {  // out = S (b - A x - E x)
    solver::multiply(A, x, out);
    const std::size_t N = out.size();
    for (std::size_t k = 0; k < N; ++k) out[k] = b[k] - out[k];
    if (E) E->apply_add(x.data(), out.data(), -1.0);
    solver::filter(S, out);
    double s = 0;
    for (std::size_t k = 0; k < N; ++k) s += out[k] * out[k];
    return s;
  }
  double apply_operator(const Vec& c, Vec& q) const {  // q = S (A + E) c
    solver::multiply(A, c, q);
    if (E) E->apply_add(c.data(), q.data(), 1.0);
    solver::filter(S, q);
    double s = 0;
    for (std::size_t k = 0; k < q.size(); ++k) s += c[k] * q[k];
    return s;
  }
  double precondition(const Vec& r, Vec& s) {  // s = S A~^-1 r
    if (!factor(r.data(), s.data())) {
      factor_ok = false;
      return 0.0;  // the iteration stops: non-positive preconditioner
    }
    solver::filter(S, s);
    double d = 0;
    for (std::size_t k = 0; k < s.size(); ++k) d += r[k] * s[k];
    return d;
  }
  double update(double alpha, const Vec& c, const Vec& q, Vec& x, Vec& r) const {
    double rr = 0;
    for (std::size_t k = 0; k < x.size(); ++k) {
      x[k] += alpha * c[k];
      r[k] -= alpha * q[k];
      rr += r[k] * r[k];
    }
    return rr;
  }
  void xpby(const Vec& s, double beta, Vec& c) const {
    for (std::size_t k = 0; k < c.size(); ++k) c[k] = s[k] + beta * c[k];
  }
  void start(Vec& dv) const { solver::apply_prescribed(S, z, dv); }
  void assign_prescribed(Vec& dv) const {
    std::fill(dv.begin(), dv.end(), 0.0);
    solver::apply_prescribed(S, z, dv);
  }
  void copy(const Vec& a, Vec& c) const { std::copy(a.begin(), a.end(), c.begin()); }
};

/// The solve of S (A + E) dv = S b, (I - S) dv = z from the warm start in dv; r, c, q, s are
/// work vectors (3n). A failed run names the solver's keys in its message.
template <class Factor>
SolveReport solve(const std::string& name, const BsrMatrix& A, const Filter& S, std::span<const double> b,
                  std::span<const double> z, const ExtraOperator* E, Factor& factor, double tolerance,
                  int max_iterations, std::span<double> dv, std::span<double> r, std::span<double> c,
                  std::span<double> q, std::span<double> s) {
  Ops<Factor> ops{A, S, b, z, E, factor};
  pcg::Settings set;
  set.tolerance = tolerance;
  set.max_iterations = max_iterations;
  set.name = name.c_str();
  SolveReport rep = pcg::solve(ops, set, dv, r, c, q, s);
  if (!ops.factor_ok) {
    rep.converged = false;
    rep.message = name + ": the triangular solve with A's factor failed";
  } else if (!rep.converged) {
    rep.message += " (contact_springs: factor_preconditioned_pcg, contact_max_iterations " +
                   std::to_string(max_iterations) + "; set contact_springs: assembled for the exact path)";
  }
  return rep;
}

}  // namespace loom::factor_pcg
