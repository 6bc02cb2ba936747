// The Baraff-Witkin step skeleton, written once for every backend (issue 17): one attempt
// (forces, assembly, constraints, solve, release pulling contacts and solve again, the
// backend's extra solves, friction, update, after-step fix-ups) and the retry policy (halve
// the step, recursively, with each half's own start time; else a SolverError naming step,
// time, h, iterations, residual and the solver's reason). The CPU plugin (baraff_witkin.cpp)
// and the CUDA backend (plugins/backends/cuda/cuda_integrators.cu) supply the operations:
//
//   void forces();                        f = f(x0, v0) (one force evaluation)
//   void assemble(double h);              df/dx, df/dv, A and b of the step
//   int  set_constraints(double h);       S and z (pins, contacts); returns the contact count
//   bool factorize(SolveReport& rep);     the solver's factorize / preconditioner
//   SolveReport solve();                  dv from the current S, z (warm start in dv)
//   void zero_dv();                       dv = 0
//   bool release_pulling_contacts(double h);  true when a contact was released (S, z rebuilt)
//   bool extra_solves(bool ok, double h, F solve_once);  further solves (self-contact); returns ok
//   void after_solve(double h);           friction, pin forces (dv final)
//   void update(double h);                v += dv, x += h v
//   void after_update(double h);          prescribed pin positions, landed contacts, projection
//   double& start_time();                 t0 of the (sub)step being taken
//   bool warm_start(); bool halve_on_failure(); int max_halvings();
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

#include "loom/clock.hpp"
#include "loom/common.hpp"
#include "loom/integrator.hpp"
#include "loom/kernels/friction.hpp"
#include "loom/linear_solver.hpp"

namespace loom::bw {

/// At most this many rounds of releasing the pulling contacts and solving again per step.
inline constexpr int kMaxReleaseRounds = 16;

/// Friction inside the solve (implicit_friction), once the contacts' dampers have joined A and
/// b: the step is solved with them, and again where a correction changed a damper
/// (`correct()`: true when any did), at most kernels::kFrictionSolves solves with dampers; then
/// `finish()` (held contacts). With an iterative solver (`set_tolerance_scale(s)` returns true)
/// the solves that a correction may still follow only size the dampers: they run at
/// kernels::kFrictionToleranceScale times its tolerance, and the step ends with a solve at the
/// scene's tolerance, warm-started from them: the last correction's, or one more when the
/// dampers already met the bound. `solves` counts the solves. Returns whether every solve
/// converged.
template <class Solve, class Correct, class Finish, class Scale>
bool friction_solves(Solve&& solve_once, Correct&& correct, Finish&& finish, Scale&& set_tolerance_scale,
                     long long& solves) {
  bool loose = set_tolerance_scale(kernels::kFrictionToleranceScale);
  bool ok = solve_once();
  ++solves;
  for (int r = 1; ok && r < kernels::kFrictionSolves; ++r) {
    if (!correct()) break;
    if (loose && r + 1 == kernels::kFrictionSolves) {  // no correction follows this solve
      set_tolerance_scale(1.0);
      loose = false;
    }
    ok = solve_once();
    ++solves;
  }
  if (loose) {
    set_tolerance_scale(1.0);
    if (ok) {
      ok = solve_once();
      ++solves;
    }
  }
  if (ok) finish();
  return ok;
}

/// One attempt of a step of size h from the state at start_time(); false when a solve failed
/// (dv is then zeroed: no warm start from a failed solve).
template <class Ops>
bool attempt(Ops& ops, double h, StepStats& st, SolveReport& rep) {
  const auto t0 = Clock::now();
  ops.forces();
  st.force_evaluations += 1;
  ops.assemble(h);
  const int contacts = ops.set_constraints(h);
  const auto t1 = Clock::now();
  st.assemble_seconds += seconds_between(t0, t1);
  auto solve_once = [&] {
    rep = SolveReport{};
    const bool ok = ops.factorize(rep);
    if (ok) {
      if (!ops.warm_start()) ops.zero_dv();
      const double fs = rep.factorize_seconds;
      rep = ops.solve();
      rep.factorize_seconds = fs;
      st.linear_iterations += rep.iterations;
      st.linear_residual = rep.residual;
    }
    return ok && rep.converged;
  };
  bool ok = solve_once();
  // Contacts whose constraint would pull are released, and the step is solved again, until no
  // contact pulls: a contact held down by its constrained neighbours pulls only once they are
  // free (a vertex of a fold 18 mm above the ball, told to land in one step, was kept by one
  // round of releases; docs/CONTACT.md, "Releases").
  for (int r = 0; ok && contacts > 0 && r < kMaxReleaseRounds && ops.release_pulling_contacts(h); ++r)
    ok = solve_once();
  ok = ops.extra_solves(ok, h, solve_once);
  st.solve_seconds += seconds_since(t1);
  if (!ok) {
    ops.zero_dv();
    return false;
  }
  ops.after_solve(h);
  ops.update(h);
  ops.after_update(h);
  return true;
}

/// A step of size h with the retry policy: on failure, two halves (the second starting at the
/// first's end time), up to max_halvings deep; then a SolverError. `who` prefixes the message.
template <class Ops>
void advance(Ops& ops, const State& state, double h, int depth, StepStats& st, const char* who) {
  SolveReport rep;
  const double t_start = ops.start_time();
  if (attempt(ops, h, st, rep)) return;
  if (ops.halve_on_failure() && depth < ops.max_halvings()) {
    st.retries += 1;
    advance(ops, state, 0.5 * h, depth + 1, st, who);
    ops.start_time() = t_start + 0.5 * h;  // the second half starts where the first ended
    advance(ops, state, 0.5 * h, depth + 1, st, who);
    ops.start_time() = t_start;
    return;
  }
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "%s: linear solve failed at step %lld (t = %.6g s, h = %.3g s%s): %d iterations, "
                "relative residual %.3g: ",
                who, static_cast<long long>(state.step), state.time, h, depth > 0 ? ", after halving the step" : "",
                rep.iterations, rep.residual);
  std::string msg = buf + (rep.message.empty() ? std::string("the solver reported no reason") : rep.message);
  if (ops.halve_on_failure())
    msg += " (gave up after " + std::to_string(ops.max_halvings()) + " halvings; raise max_halvings or reduce dt)";
  else if (msg.find("halve_step") == std::string::npos)
    msg += "; or set integrator.on_solver_failure: halve_step, which solves a failed step again as two halves";
  throw SolverError(msg);
}

}  // namespace loom::bw
