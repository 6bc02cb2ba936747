#include "baraff_witkin.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "loom/kernels/bsr_ops.hpp"
#include "loom/solver_common.hpp"
#include "loom/state.hpp"

namespace loom {

namespace {
using Clock = std::chrono::steady_clock;
double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}
}  // namespace

BaraffWitkinOptions parse_baraff_witkin_options(const Params& p) {
  BaraffWitkinOptions o;
  if (!p.valid()) return o;
  o.kang_cho_damping = p.get_nonnegative("kang_cho_damping", 0.0);
  if (p.has("rayleigh")) {
    const Params r = p.child("rayleigh");
    if (!r.is_map()) r.fail("rayleigh must be a mapping {alpha: <1/s>, beta: <s>}");
    o.rayleigh_alpha = r.get_nonnegative("alpha", 0.0);
    o.rayleigh_beta = r.get_nonnegative("beta", 0.0);
    r.check_unused();
  }
  const std::string pol = p.get_choice("on_solver_failure", "stop", {"stop", "halve_step"});
  o.on_failure = pol == "stop" ? BaraffWitkinOptions::OnFailure::Stop : BaraffWitkinOptions::OnFailure::HalveStep;
  const std::int64_t mh = p.get("max_halvings", static_cast<std::int64_t>(o.max_halvings));
  if (mh < 1 || mh > 20) p.child("max_halvings").fail("max_halvings must be between 1 and 20");
  o.max_halvings = static_cast<int>(mh);
  o.warm_start = p.get("warm_start", o.warm_start);
  return o;
}

BaraffWitkin::BaraffWitkin(BaraffWitkinOptions options) : options_(options) {}

void BaraffWitkin::prepare(Scene& scene, double h) {
  if (!(h > 0) || !std::isfinite(h))
    throw InputError("baraff_witkin: the time step must be positive and finite; set integrator.dt");
  if (!scene.material)
    throw InputError("baraff_witkin: the scene has no material; add a material: section");
  if (!scene.material->has_jacobian())
    throw InputError("baraff_witkin: material '" + scene.material->name() +
                     "' provides no force Jacobians, which the implicit step needs; use a material with "
                     "Jacobians (mass_spring, gnatv) or an explicit integrator (symplectic_euler, rk4)");
  if (!scene.solver)
    throw InputError("baraff_witkin: no linear solver is configured; add a solver: section, e.g. "
                     "solver: {type: [eigen_pcg, eigen_ldlt]}");
  State& s = scene.state;
  const Index n = s.size();
  if (static_cast<Index>(s.x.size()) != 3 * n || static_cast<Index>(s.v.size()) != 3 * n)
    throw InputError("baraff_witkin: the state's positions/velocities do not match its vertex count");
  n_ = n;

  std::vector<std::array<Index, 2>> pairs;
  scene.material->jacobian_pairs(pairs);
  for (const auto& pr : pairs)
    if (pr[0] < 0 || pr[1] < 0 || pr[0] >= n || pr[1] >= n)
      throw InputError("baraff_witkin: material '" + scene.material->name() + "' reported a Jacobian pair (" +
                       std::to_string(pr[0]) + ", " + std::to_string(pr[1]) + ") outside the mesh");
  // A fresh pattern object: matrices of a previous prepare() keep pointing at the old one
  // until they are replaced below.
  pattern_ = std::make_unique<BsrPattern>(BsrPattern::from_pairs(n, pairs));
  scene.material->bind_pattern(*pattern_);
  dfdx_ = BsrMatrix(pattern_.get());
  dfdv_ = BsrMatrix(pattern_.get());
  A_ = BsrMatrix(pattern_.get());

  degree_.assign(n, 0.0);
  for (Index i = 0; i < n; ++i) degree_[i] = static_cast<double>(pattern_->row_ptr[i + 1] - pattern_->row_ptr[i] - 1);

  const std::size_t N = 3 * static_cast<std::size_t>(n);
  f_.assign(N, 0.0);
  b_.assign(N, 0.0);
  z_.assign(N, 0.0);
  dv_.assign(N, 0.0);

  S_.reset(n);
  for (Index i : s.pin_list) S_.constrain_all(i);
  scene.solver->analyze_pattern(A_, S_);
  last_ = {};
}

void BaraffWitkin::set_constraints(const State& s, double h) {
  if (hook_) {
    S_.reset(n_);
    for (Index i : s.pin_list) S_.constrain_all(i);
    std::fill(z_.begin(), z_.end(), 0.0);
  }
  // Fixed pins: prescribed velocity 0, so dv = -v0 there.
  for (Index i : s.pin_list) {
    const std::size_t o = 3 * static_cast<std::size_t>(i);
    z_[o] = -s.v[o];
    z_[o + 1] = -s.v[o + 1];
    z_[o + 2] = -s.v[o + 2];
  }
  if (hook_) hook_(s, h, S_, z_);
}

void BaraffWitkin::assemble(const Scene& scene, double h) {
  const State& s = scene.state;
  const BsrPattern& P = *pattern_;
  const Index n = n_;
  const double alpha = options_.rayleigh_alpha, beta = options_.rayleigh_beta, cd = options_.kang_cho_damping;
  const double cm = 1.0 + h * alpha;       // on M
  const double cx = h * h + h * beta;      // on -df/dx in A
  const double cbx = h + beta;             // on df/dx v0 inside b / h
  const double hcd = h * cd;
  const double g0 = scene.gravity[0], g1 = scene.gravity[1], g2 = scene.gravity[2];
  const Index* rp = P.row_ptr.data();
  const Index* col = P.col.data();
  const double* dfx = dfdx_.values().data();
  const double* dfv = dfdv_.values().data();
  double* a = A_.values().data();
  const double* v = s.v.data();
  const double* f = f_.data();
  const double* mass = s.mass.data();
  double* b = b_.data();
#pragma omp parallel for schedule(static) if (n >= solver::kParallelMinRows)
  for (Index i = 0; i < n; ++i) {
    const std::size_t o = 3 * static_cast<std::size_t>(i);
    double y[3] = {0, 0, 0};   // df/dx v0 (row i)
    double sv[3] = {0, 0, 0};  // sum of neighbour velocities
    for (Index k = rp[i]; k < rp[i + 1]; ++k) {
      const std::size_t kb = 9 * static_cast<std::size_t>(k);
      const Index j = col[k];
      const double* vj = v + 3 * static_cast<std::size_t>(j);
      kernels::mat3_mul_add(dfx + kb, vj, y);
      double* ak = a + kb;
      for (int e = 0; e < 9; ++e) ak[e] = -h * dfv[kb + e] - cx * dfx[kb + e];
      if (j == i) {
        const double d = cm * mass[i] + hcd * degree_[i];
        ak[0] += d;
        ak[4] += d;
        ak[8] += d;
      } else {
        ak[0] -= hcd;
        ak[4] -= hcd;
        ak[8] -= hcd;
        sv[0] += vj[0];
        sv[1] += vj[1];
        sv[2] += vj[2];
      }
    }
    const double m = mass[i], deg = degree_[i];
    const double g[3] = {g0, g1, g2};
    for (int c = 0; c < 3; ++c) {
      const double lv = deg * v[o + c] - sv[c];  // (L v0)_i
      b[o + c] = h * (f[o + c] + m * g[c] - alpha * m * v[o + c] + cbx * y[c] - cd * lv);
    }
  }
}

bool BaraffWitkin::attempt(Scene& scene, double h, StepStats& st, SolveReport& rep) {
  State& s = scene.state;
  const auto t0 = Clock::now();
  scene.material->compute_forces(s.x, s.v, f_);
  st.force_evaluations += 1;
  scene.material->compute_jacobians(s.x, s.v, dfdx_, &dfdv_);
  assemble(scene, h);
  set_constraints(s, h);
  const auto t1 = Clock::now();
  st.assemble_seconds += seconds_between(t0, t1);

  rep = SolveReport{};
  const bool ok = scene.solver->factorize(A_, S_, rep);
  if (ok) {
    if (!options_.warm_start) std::fill(dv_.begin(), dv_.end(), 0.0);
    const double fs = rep.factorize_seconds;
    rep = scene.solver->solve(A_, S_, b_, z_, dv_);
    rep.factorize_seconds = fs;
    st.linear_iterations += rep.iterations;
    st.linear_residual = rep.residual;
  }
  st.solve_seconds += seconds_between(t1, Clock::now());
  if (!ok || !rep.converged) {
    std::fill(dv_.begin(), dv_.end(), 0.0);  // no warm start from a failed solve
    return false;
  }

  const Index n = n_;
  double* x = s.x.data();
  double* v = s.v.data();
  const double* dv = dv_.data();
#pragma omp parallel for schedule(static) if (n >= solver::kParallelMinRows)
  for (Index i = 0; i < n; ++i) {
    const std::size_t o = 3 * static_cast<std::size_t>(i);
    for (int c = 0; c < 3; ++c) {
      v[o + c] += dv[o + c];
      x[o + c] += h * v[o + c];
    }
  }
  return true;
}

void BaraffWitkin::advance(Scene& scene, double h, int depth, StepStats& st) {
  SolveReport rep;
  if (attempt(scene, h, st, rep)) return;
  if (options_.on_failure == BaraffWitkinOptions::OnFailure::HalveStep && depth < options_.max_halvings) {
    st.retries += 1;
    advance(scene, 0.5 * h, depth + 1, st);
    advance(scene, 0.5 * h, depth + 1, st);
    return;
  }
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "baraff_witkin: linear solve failed at step %lld (t = %.6g s, h = %.3g s%s): %d iterations, "
                "relative residual %.3g: ",
                static_cast<long long>(scene.state.step), scene.state.time, h,
                depth > 0 ? ", after halving the step" : "", rep.iterations, rep.residual);
  std::string msg = buf + (rep.message.empty() ? std::string("the solver reported no reason") : rep.message);
  if (options_.on_failure == BaraffWitkinOptions::OnFailure::HalveStep)
    msg += " (gave up after " + std::to_string(options_.max_halvings) + " halvings; raise max_halvings or reduce dt)";
  throw SolverError(msg);
}

void BaraffWitkin::step(Scene& scene, double h) {
  if (n_ != scene.state.size() || !pattern_) prepare(scene, h);
  StepStats st;
  advance(scene, h, 0, st);
  finish_step(scene.state, h);
  last_ = st;
}

}  // namespace loom
