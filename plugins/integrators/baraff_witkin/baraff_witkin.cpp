#include "baraff_witkin.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "loom/clock.hpp"
#include "loom/kernels/bsr_ops.hpp"
#include "loom/kernels/bw_assembly.hpp"
#include "loom/solver_common.hpp"
#include "loom/state.hpp"
#include "bw_step.hpp"

namespace loom {

const ParamSpec& baraff_witkin_spec() {
  static const ParamSpec spec = [] {
    const BaraffWitkinOptions d;
    ParamSpec s("baraff_witkin", "linearised implicit Euler (Baraff & Witkin 1998) with the constraint filter");
    s.number("kang_cho_damping", d.kang_cho_damping).range(ParamRange::nonnegative()).units("N s/m").help(
        "c_d of the graph-Laplacian damper (NUMERICS 3.2)");
    ParamSpec ray("rayleigh");
    ray.number("alpha", d.rayleigh_alpha).range(ParamRange::nonnegative()).units("1/s").help("mass-proportional damping");
    ray.number("beta", d.rayleigh_beta).range(ParamRange::nonnegative()).units("s").help("stiffness-proportional damping");
    s.map("rayleigh", std::move(ray)).help("Rayleigh damping {alpha, beta}");
    s.choice("on_solver_failure", d.on_failure == BaraffWitkinOptions::OnFailure::Stop ? "stop" : "halve_step",
             {"stop", "halve_step"})
        .help("when the linear solver fails: stop the run, or retry the step as two halves");
    s.integer("max_halvings", d.max_halvings).range(ParamRange::closed(1, 20)).help(
        "nesting depth of halve_step retries");
    s.flag("warm_start", d.warm_start).help("start each solve from the previous step's dv");
    s.flag("implicit_self_contact", d.implicit_self_contact).backends({"cpu"}).help(
        "self-contacts of self_collision as stiff springs inside the implicit solve (docs/CONTACT.md)");
    s.flag("implicit_friction", d.implicit_friction).help(
        "Coulomb friction of contacts as tangential dampers inside the solve (up to 3 more solves), "
        "instead of a velocity correction after it (docs/CONTACT.md; on cuda: the colliders' contacts)");
    declare_device_keys(s);
    return s;
  }();
  return spec;
}

BaraffWitkinOptions parse_baraff_witkin_options(const Params& p, const std::string& backend) {
  BaraffWitkinOptions o;
  if (!p.valid()) return o;
  const ParamReader r(p, baraff_witkin_spec());
  o.kang_cho_damping = r.number("kang_cho_damping");
  if (p.has("rayleigh")) {
    const ParamReader ray = r.section("rayleigh");
    if (!ray.params().is_map()) ray.params().fail("rayleigh must be a mapping {alpha: <1/s>, beta: <s>}");
    o.rayleigh_alpha = ray.number("alpha");
    o.rayleigh_beta = ray.number("beta");
    ray.params().check_unused();
  }
  const std::string pol = r.text("on_solver_failure");
  o.on_failure = pol == "stop" ? BaraffWitkinOptions::OnFailure::Stop : BaraffWitkinOptions::OnFailure::HalveStep;
  o.max_halvings = r.int32("max_halvings");
  o.warm_start = r.flag("warm_start");
  // cpu only: a device backend leaves the key unread, so check_unused names the backend that
  // honours it instead of accepting it silently.
  if (backend == "cpu") o.implicit_self_contact = r.flag("implicit_self_contact");
  o.implicit_friction = r.flag("implicit_friction");
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
  material_pairs_ = pairs;
  material_pattern_ = *pattern_;
  pattern_rebuilds_ = 0;
  friction_solves_ = 0;
  self_contact_.reset();
  if (scene.self_collision && options_.implicit_self_contact) {
    self_contact_ = std::make_unique<ImplicitSelfContact>();
    self_contact_->prepare(scene.mesh, scene.self_collision->options().thickness,
                           scene.self_collision->options().friction);
    // Matrix-free when the solver can apply the springs itself: the pattern never grows.
    self_contact_->set_matrix_free(scene.solver->supports_extra_operator());
    self_contact_->bind(*pattern_, material_pattern_);
  }
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
  scene.pins.constraint_forces().assign(3 * s.pin_list.size(), 0.0);
  contacts_.clear();
  if (!scene.colliders.empty()) contacts_.reserve(n);
  in_contact_.assign(scene.colliders.empty() ? 0 : n, 0);
  warm_D_.assign(scene.colliders.empty() ? 0 : n, 0.0);
  frames0_.resize(scene.colliders.size());
  frames1_.resize(scene.colliders.size());
  scene.solver->set_extra_operator(nullptr);
  edv_.assign(self_contact_matrix_free() && !s.pin_list.empty() ? N : 0, 0.0);
  scene.solver->analyze_pattern(A_, S_);
  last_ = {};
}

void BaraffWitkin::set_constraints(const Scene& scene, double h) {
  const State& s = scene.state;
  const bool contacts = !scene.colliders.empty();
  if (hook_ || contacts) {
    S_.reset(n_);
    for (Index i : s.pin_list) S_.constrain_all(i);
    std::fill(z_.begin(), z_.end(), 0.0);
  }
  // Pins: dv = v1 - v0 with v1 = 0 for fixed pins and v1 = (p(t + h) - x0)/h for moving
  // ones, so that x1 = x0 + h v1 is the prescribed position (docs/NUMERICS.md, moving pins).
  scene.pins.write_dv(s, t0_ + h, h, z_);
  if (hook_) hook_(s, h, S_, z_);
  contacts_.clear();
  if (!contacts) return;
  // A free vertex inside a collider's offset surface, or predicted to enter it during the
  // step, loses its normal DOF (Baraff & Witkin 1998, sec. 5). Its normal velocity is
  // prescribed to the surface's minus the remaining distance over h, so that it ends the
  // step exactly on the surface: a vertex still in the air closes the gap within the step
  // (lands), a vertex on the surface moves with it, one inside leaves the penetration.
  const double t0 = t0_, t1 = t0_ + h;  // t0_: this (half) step's start, also when halving
  const auto& cols = scene.colliders.colliders();
  for (std::size_t c = 0; c < cols.size(); ++c) {
    frames0_[c] = cols[c].frame_at(t0);
    frames1_[c] = cols[c].frame_at(t1);
  }
  for (Index i = 0; i < n_; ++i) {
    if (s.pinned[i] || S_.free_dofs(i) < 3) continue;
    const double* x = &s.x[3 * static_cast<std::size_t>(i)];
    const double* v = &s.v[3 * static_cast<std::size_t>(i)];
    // Predicted end-of-step position of an explicit step (forces and gravity included), so a
    // vertex resting on a surface, whose velocity is zero, is still seen to press into it.
    const double* f = &f_[3 * static_cast<std::size_t>(i)];
    const double w = s.inv_mass[i];
    double vp[3], xp[3];
    for (int k = 0; k < 3; ++k) {
      vp[k] = v[k] + h * (w * f[k] + scene.gravity[k]);
      xp[k] = x[k] + h * vp[k];
    }
    const Collider* best = nullptr;
    Collider::Contact bc{};
    double depth = 0;
    for (std::size_t ci = 0; ci < cols.size(); ++ci) {
      const Collider& c = cols[ci];
      // Only distances <= kContactTolerance make a contact: ask with a cutoff (exact below it,
      // a lower bound above; a mesh skips its far parts), and again without it for the start
      // distance of a vertex predicted to land, whose target velocity needs it exactly.
      // The tolerance, not 0: a vertex that the last step left on the surface (projected, or
      // sliding) starts at a distance of a rounding error, either sign; with 0 as the limit
      // that sign decided whether it stayed in contact, so the same run on another thread
      // count or backend could part by a whole contact (test_cuda_mesh_colliders.cpp).
      Collider::Contact now = c.query(frames0_[ci], x, kQueryCutoff);
      const Collider::Contact next = c.query(frames1_[ci], xp, kQueryCutoff);
      if (next.distance <= kContactTolerance && now.distance >= kQueryCutoff) now = c.query(frames0_[ci], x);
      const double d = std::min(now.distance, next.distance);
      if (d <= kContactTolerance && (!best || d < depth)) {
        best = &c;
        bc = next.distance < now.distance ? next : now;
        bc.distance = now.distance;
        depth = d;
      }
    }
    if (!best) continue;
    Contact ct{};
    ct.vertex = i;
    for (int k = 0; k < 3; ++k) {
      ct.normal[k] = bc.normal[k];
      ct.surface_velocity[k] = bc.velocity[k];
    }
    ct.mu_static = best->mu_static;
    ct.mu_kinetic = best->mu_kinetic;
    const double vn = v[0] * ct.normal[0] + v[1] * ct.normal[1] + v[2] * ct.normal[2];
    const double vpn = vp[0] * ct.normal[0] + vp[1] * ct.normal[1] + vp[2] * ct.normal[2];
    const double sn = ct.surface_velocity[0] * ct.normal[0] + ct.surface_velocity[1] * ct.normal[1] +
                      ct.surface_velocity[2] * ct.normal[2];
    const double target = sn - bc.distance / h;  // normal velocity that ends the step on the surface
    if (vpn > target) continue;  // does not reach the surface within the step: no constraint
    // In contact now (friction acts) or landing during the step (no friction: the cloth is in
    // the air until the end of the step, and the impact impulse makes none either).
    ct.landing = bc.distance > kContactTolerance && !in_contact_[i];
    S_.constrain_direction(i, ct.normal);
    ct.dvn = target - vn;
    double* zi = &z_[3 * static_cast<std::size_t>(i)];
    for (int k = 0; k < 3; ++k) zi[k] = ct.dvn * ct.normal[k];
    contacts_.push_back(ct);
  }
}

// The constraint impulse on a contact vertex is the normal part of (A dv - b)_i. A negative
// one means the surface would have to pull the vertex: release it (Baraff & Witkin) and let
// the caller solve again. Returns whether anything was released.
bool BaraffWitkin::release_pulling_contacts(const Scene& scene, double h) {
  const BsrPattern& P = *pattern_;
  const double* a = A_.values().data();
  bool released = false;
  std::size_t keep = 0;
  for (std::size_t c = 0; c < contacts_.size(); ++c) {
    Contact& ct = contacts_[c];
    const Index i = ct.vertex;
    double r[3] = {0, 0, 0};
    for (Index k = P.row_ptr[i]; k < P.row_ptr[i + 1]; ++k)
      kernels::mat3_mul_add(a + 9 * static_cast<std::size_t>(k), &dv_[3 * static_cast<std::size_t>(P.col[k])], r);
    const double* bi = &b_[3 * static_cast<std::size_t>(i)];
    ct.impulse = (r[0] - bi[0]) * ct.normal[0] + (r[1] - bi[1]) * ct.normal[1] + (r[2] - bi[2]) * ct.normal[2];
    if (ct.impulse < 0) {
      released = true;
      continue;
    }
    contacts_[keep++] = ct;
  }
  contacts_.resize(keep);
  if (!released) return false;
  // Rebuild S and z: pins, the hook, and the contacts that push.
  const State& s = scene.state;
  S_.reset(n_);
  std::fill(z_.begin(), z_.end(), 0.0);
  for (Index i : s.pin_list) S_.constrain_all(i);
  scene.pins.write_dv(s, t0_ + h, h, z_);
  if (hook_) hook_(s, h, S_, z_);
  for (const Contact& ct : contacts_) {
    const std::size_t o = 3 * static_cast<std::size_t>(ct.vertex);
    S_.constrain_direction(ct.vertex, ct.normal);
    for (int k = 0; k < 3; ++k) z_[o + k] = ct.dvn * ct.normal[k];
  }
  return true;
}

// Coulomb friction as a velocity-level correction (Baraff & Witkin): the normal impulse per
// unit mass j = impulse / m bounds the tangential velocity change relative to the surface.
void BaraffWitkin::apply_friction(const Scene& scene) {
  const State& s = scene.state;
  for (const Contact& ct : contacts_) {
    if (ct.landing || (ct.mu_static <= 0 && ct.mu_kinetic <= 0)) continue;
    const std::size_t o = 3 * static_cast<std::size_t>(ct.vertex);
    const double j = std::max(0.0, ct.impulse) * s.inv_mass[ct.vertex];
    double vrel[3];
    for (int k = 0; k < 3; ++k) vrel[k] = s.v[o + k] + dv_[o + k] - ct.surface_velocity[k];
    const double vn = vrel[0] * ct.normal[0] + vrel[1] * ct.normal[1] + vrel[2] * ct.normal[2];
    double vt[3];
    for (int k = 0; k < 3; ++k) vt[k] = vrel[k] - vn * ct.normal[k];
    const double len = std::sqrt(vt[0] * vt[0] + vt[1] * vt[1] + vt[2] * vt[2]);
    double keep = 1.0;
    if (len <= ct.mu_static * j) keep = 0.0;
    else if (len > 0) keep = std::max(0.0, 1.0 - ct.mu_kinetic * j / len);
    for (int k = 0; k < 3; ++k) dv_[o + k] -= (1.0 - keep) * vt[k];
  }
}

// Coulomb friction inside the solve (BaraffWitkinOptions::implicit_friction): a contact vertex
// that is not landing gets a damper on its velocity relative to the surface in the tangent
// plane, f = -c P (v1 - v_s), P = I - n n^T: A_ii += h c P, b_i += -h c P (v0 - v_s), with h c
// from coulomb_damping: the normal impulse of the last solve, the tangential relative speed it
// gave, and the vertex's mass as its response (exact for a vertex alone or a sheet sliding as
// one). The per-vertex rules are loom/kernels/friction.hpp's, which the CUDA backend runs too.
// Returns whether any vertex got a damper.
bool BaraffWitkin::add_collider_friction(const Scene& scene) {
  const State& s = scene.state;
  bool any = false;
  for (Contact& ct : contacts_) {
    const std::size_t o = 3 * static_cast<std::size_t>(ct.vertex);
    ct.fr = {};
    if (ct.landing) continue;
    const double D = warm_D_[ct.vertex] > 0 ? warm_D_[ct.vertex] : s.mass[ct.vertex];  // warm start, or the mass
    any |= kernels::start_collider_friction(&s.v[o], &dv_[o], ct.surface_velocity, ct.normal, D,
                                            ct.mu_static, ct.mu_kinetic, ct.impulse, diagonal_block(ct.vertex),
                                            &b_[o], ct.fr);
  }
  std::fill(warm_D_.begin(), warm_D_.end(), 0.0);  // set again by finish_collider_friction
  return any;
}

double* BaraffWitkin::diagonal_block(Index i) { return A_.block(pattern_->diag[i]); }

// After a solve with the dampers: where a vertex's friction impulse misses the Coulomb bound
// by more than kernels::kCoulombTolerance, its damper is chosen again
// (kernels::correct_collider_friction). Returns whether any changed (solve again).
bool BaraffWitkin::correct_collider_friction(const Scene& scene) {
  const State& s = scene.state;
  bool changed = false;
  for (Contact& ct : contacts_) {
    const std::size_t o = 3 * static_cast<std::size_t>(ct.vertex);
    if (ct.fr.hc == 0) continue;
    changed |= kernels::correct_collider_friction(&s.v[o], &dv_[o], ct.surface_velocity, ct.normal,
                                                  s.mass[ct.vertex], ct.mu_static, ct.mu_kinetic, ct.impulse,
                                                  diagonal_block(ct.vertex), &b_[o], ct.fr);
  }
  return changed;
}

// After a solve with the dampers: the contacts' friction against their Coulomb bounds, summed
// (kernels::FrictionTally; the corrections stop once it is settled()).
kernels::FrictionTally<double> BaraffWitkin::collider_friction_tally(const Scene& scene) const {
  const State& s = scene.state;
  kernels::FrictionTally<double> t;
  for (const Contact& ct : contacts_) {
    if (ct.fr.hc == 0) continue;
    const std::size_t o = 3 * static_cast<std::size_t>(ct.vertex);
    double excess, bound;
    const double miss = kernels::collider_friction_miss(&s.v[o], &dv_[o], ct.surface_velocity, ct.normal,
                                                        ct.mu_static, ct.mu_kinetic, ct.impulse, ct.fr, excess, bound);
    t.add(miss, excess, bound);
  }
  return t;
}

// After the last solve: a vertex held by static friction loses the tangential velocity the
// finite damper leaves (about 1/kStickDamping of its slip without friction).
void BaraffWitkin::finish_collider_friction(const Scene& scene) {
  const State& s = scene.state;
  for (const Contact& ct : contacts_) {
    const std::size_t o = 3 * static_cast<std::size_t>(ct.vertex);
    warm_D_[ct.vertex] =
        kernels::collider_friction_response(&s.v[o], &dv_[o], ct.surface_velocity, ct.normal, s.mass[ct.vertex], ct.fr);
    kernels::finish_collider_friction(&s.v[o], &dv_[o], ct.surface_velocity, ct.normal, ct.fr);
  }
}

// A vertex that landed during the step arrives on the surface with its approach velocity
// (the one that closed the gap). The impact is inelastic: at the end of the step its normal
// velocity becomes the surface's, as resolve_contacts does for the explicit integrators, so
// that the next step does not see the approach speed as a push into the surface (whose
// impulse would then make a spurious friction). The tangential velocity is kept.
void BaraffWitkin::stop_landed(Scene& scene) {
  State& s = scene.state;
  for (const Contact& ct : contacts_) {
    if (!ct.landing) continue;
    double* v = &s.v[3 * static_cast<std::size_t>(ct.vertex)];
    const double rel = (v[0] - ct.surface_velocity[0]) * ct.normal[0] + (v[1] - ct.surface_velocity[1]) * ct.normal[1] +
                       (v[2] - ct.surface_velocity[2]) * ct.normal[2];
    if (rel < 0)
      for (int k = 0; k < 3; ++k) v[k] -= rel * ct.normal[k];
  }
}

// Residual penetration after the step (the velocity constraints stop further approach, but a
// vertex the prediction missed, or a released one, may end slightly inside): move positions
// onto the offset surface, velocities untouched.
void BaraffWitkin::project_positions(Scene& scene, double t) {
  State& s = scene.state;
  const auto& cols = scene.colliders.colliders();
  for (std::size_t c = 0; c < cols.size(); ++c) frames1_[c] = cols[c].frame_at(t);
  for (Index i = 0; i < n_; ++i) {
    if (s.pinned[i]) continue;
    double* x = &s.x[3 * static_cast<std::size_t>(i)];
    for (std::size_t ci = 0; ci < cols.size(); ++ci) {
      const Collider::Contact q = cols[ci].query(frames1_[ci], x, 0.0);  // exact where < 0
      if (q.distance < 0)
        for (int k = 0; k < 3; ++k) x[k] -= q.distance * q.normal[k];
    }
  }
}

// The pattern: the material's pairs plus the self-contacts' (ImplicitSelfContact::reserve_pairs,
// at most as many as the material's). The material binds to it again and the solver analyses
// it again; this happens only when a contact needs a block the pattern lacks.
void BaraffWitkin::rebuild_pattern(Scene& scene) {
  const auto& extra = self_contact_->reserve_pairs(material_pairs_.size());
  pattern_pairs_.assign(material_pairs_.begin(), material_pairs_.end());
  pattern_pairs_.insert(pattern_pairs_.end(), extra.begin(), extra.end());
  pattern_ = std::make_unique<BsrPattern>(BsrPattern::from_pairs(n_, pattern_pairs_));
  scene.material->bind_pattern(*pattern_);
  dfdx_ = BsrMatrix(pattern_.get());
  dfdv_ = BsrMatrix(pattern_.get());
  A_ = BsrMatrix(pattern_.get());
  if (!self_contact_->bind(*pattern_, material_pattern_))
    throw std::logic_error("baraff_witkin: the rebuilt pattern lacks a self-contact block");
  scene.solver->analyze_pattern(A_, S_);
  ++pattern_rebuilds_;
}

void BaraffWitkin::assemble(const Scene& scene, double h) {
  const State& s = scene.state;
  const BsrPattern& P = *pattern_;
  const Index n = n_;
  const double alpha = options_.rayleigh_alpha, beta = options_.rayleigh_beta, cd = options_.kang_cho_damping;
  const kernels::BwAssemble<double> row{P.row_ptr.data(), P.col.data(), dfdx_.values().data(), dfdv_.values().data(),
                                        s.v.data(), f_.data(), s.mass.data(), degree_.data(), A_.values().data(),
                                        b_.data(), h, 1.0 + h * alpha, h * h + h * beta, h + beta, h * cd, alpha, cd,
                                        scene.gravity[0], scene.gravity[1], scene.gravity[2]};
#pragma omp parallel for schedule(static) if (n >= solver::kParallelMinRows)
  for (Index i = 0; i < n; ++i) row(i);
}

// The operations of the shared step skeleton (bw_step.hpp) on the CPU.
struct BaraffWitkin::StepOps {
  BaraffWitkin& bw;
  Scene& scene;

  void forces() { scene.material->compute_forces(scene.state.x, scene.state.v, bw.f_); }
  void assemble(double h) {
    const State& s = scene.state;
    scene.material->compute_jacobians(s.x, s.v, bw.dfdx_, &bw.dfdv_);
    if (bw.self_contact_) {  // blocks the pattern holds for self-contacts only
      bw.self_contact_->zero_extra_blocks(bw.dfdx_);
      bw.self_contact_->zero_extra_blocks(bw.dfdv_);
    }
    bw.assemble(scene, h);
    if (bw.self_contact_) bw.self_contact_->undo_laplacian(bw.A_, bw.b_, s.v, h * bw.options_.kang_cho_damping);
  }
  int set_constraints(double h) {
    bw.set_constraints(scene, h);
    return static_cast<int>(bw.contacts_.size());
  }
  bool factorize(SolveReport& rep) {
    scene.solver->set_coordinates(scene.state.x);
    return scene.solver->factorize(bw.A_, bw.S_, rep);
  }
  SolveReport solve() {
    SolveReport r = scene.solver->solve(bw.A_, bw.S_, bw.b_, bw.z_, bw.dv_);
    if (bw.self_contact_) bw.self_contact_->mutable_stats().iterations += r.iterations;  // reset by find()
    return r;
  }
  void zero_dv() { std::fill(bw.dv_.begin(), bw.dv_.end(), 0.0); }
  bool release_pulling_contacts(double h) { return bw.release_pulling_contacts(scene, h); }
  // Self-contacts (self_contact.hpp): the pairs this step brings within the thickness become
  // springs (a contact whose blocks the pattern lacks extends it first) and the step is solved
  // again with them; springs that would pull are released and the step solved again.
  template <class F>
  bool extra_solves(bool ok, double h, F&& solve_once) {
    State& s = scene.state;
    if (ok && bw.self_contact_ && bw.self_contact_->find(*scene.self_collision, s, bw.dv_, h, *bw.pattern_)) {
      auto& sst = bw.self_contact_->mutable_stats();
      if (!bw.self_contact_->blocks_complete()) {
        const double tp = thread_seconds();
        bw.rebuild_pattern(scene);
        assemble(h);
        sst.pattern_seconds = thread_seconds() - tp;
      }
      const double ts = thread_seconds();
      bw.self_contact_->add_terms(bw.A_, bw.b_, s.v, h);
      const bool mf = bw.self_contact_->matrix_free();
      if (mf) scene.solver->set_extra_operator(bw.self_contact_.get());  // the springs' matrix term
      // The solves before the last only decide which springs are released: an iterative
      // solver runs them at a looser tolerance (ImplicitSelfContact::kReleaseToleranceScale),
      // and one solve at the scene's tolerance, warm-started from them, ends the step.
      const bool loose = scene.solver->set_tolerance_scale(ImplicitSelfContact::kReleaseToleranceScale);
      ok = solve_once();
      ++sst.solves;
      for (int r = 0; ok && r < ImplicitSelfContact::kMaxReleaseSolves &&
                      bw.self_contact_->release(bw.A_, bw.b_, s.v, bw.dv_, h);
           ++r) {
        ok = solve_once();
        ++sst.solves;
      }
      if (loose) {
        scene.solver->set_tolerance_scale(1.0);
        if (ok) {
          ok = solve_once();
          ++sst.solves;
        }
      }
      if (mf) scene.solver->set_extra_operator(nullptr);
      sst.solve_seconds = thread_seconds() - ts;
    }
    if (ok && bw.options_.implicit_friction) ok = friction_solve(h, solve_once);
    return ok;
  }
  // Friction inside the solve: the contacts' tangential dampers join A and b (the springs of
  // the self-contacts stay) and bw::friction_solves solves the step with them, corrects them
  // and solves again (bw_step.hpp, one source with the CUDA backend). The normal impulses that
  // bound the dampers come from the springs' (and the collider contacts') solves at the
  // scene's tolerance.
  template <class F>
  bool friction_solve(double h, F&& solve_once) {
    State& s = scene.state;
    bw.collider_tally_ = {};
    bw.pair_tally_ = {};
    const bool col = !bw.contacts_.empty() && bw.add_collider_friction(scene);
    const bool pairs = bw.self_contact_ && !bw.self_contact_->contacts().empty();
    if (bw.self_contact_ && !pairs) bw.self_contact_->forget_warm_responses();
    const bool self = pairs && bw.self_contact_->add_friction(s, bw.A_, bw.b_, bw.dv_, h);
    if (!col && !self) return true;
    const bool mf = bw.self_contact_ && bw.self_contact_->matrix_free() && !bw.self_contact_->contacts().empty();
    if (mf) scene.solver->set_extra_operator(bw.self_contact_.get());
    // Each kind is corrected while its contacts miss their bounds, in sum, by more than
    // kernels::kFrictionStopTolerance of the bounds' sum (FrictionTally::settled); the step's
    // friction solves stop when neither kind changed.
    auto tally = [&] {
      if (col) bw.collider_tally_ = bw.collider_friction_tally(scene);
      if (self) bw.pair_tally_ = bw.self_contact_->friction_tally(s, bw.dv_);
    };
    const bool ok = bw::friction_solves(
        solve_once,
        [&] {  // both corrected before the next solve: no short-circuit
          tally();
          const bool c1 = col && !bw.collider_tally_.settled() && bw.correct_collider_friction(scene);
          const bool c2 =
              self && !bw.pair_tally_.settled() && bw.self_contact_->correct_friction(s, bw.A_, bw.b_, bw.dv_);
          return c1 || c2;
        },
        [&] {
          tally();  // what the step's last solve left
          if (col) bw.finish_collider_friction(scene);
          if (self) bw.self_contact_->finish_friction(s, bw.dv_);
        },
        [&](double k) { return scene.solver->set_tolerance_scale(k); }, bw.friction_solves_);
    if (mf) scene.solver->set_extra_operator(nullptr);
    return ok;
  }
  void after_solve(double h) {
    if (!bw.options_.implicit_friction) {
      if (!bw.contacts_.empty()) bw.apply_friction(scene);
      if (bw.self_contact_) bw.self_contact_->apply_friction(scene.state, bw.dv_, h);
    }
    bw.record_pin_forces(scene, h);
  }
  void update(double h) {
    State& s = scene.state;
    const Index n = bw.n_;
    double* x = s.x.data();
    double* v = s.v.data();
    const double* dv = bw.dv_.data();
#pragma omp parallel for schedule(static) if (n >= solver::kParallelMinRows)
    for (Index i = 0; i < n; ++i) {
      const std::size_t o = 3 * static_cast<std::size_t>(i);
      for (int c = 0; c < 3; ++c) {
        v[o + c] += dv[o + c];
        x[o + c] += h * v[o + c];
      }
    }
  }
  void after_update(double h) {
    State& s = scene.state;
    // Moving pins: x0 + h v1 equals p(t + h) up to rounding; store it exactly.
    scene.pins.apply_positions(s, bw.t0_ + h);
    if (!bw.contacts_.empty()) bw.stop_landed(scene);
    if (bw.self_contact_) {
      bw.self_contact_->clear_friction();
      bw.self_contact_->stop_approach(s);
    }
    if (!bw.in_contact_.empty()) {
      std::fill(bw.in_contact_.begin(), bw.in_contact_.end(), 0);
      for (const Contact& ct : bw.contacts_) bw.in_contact_[ct.vertex] = 1;
    }
    if (!scene.colliders.empty()) bw.project_positions(scene, bw.t0_ + h);
  }
  double& start_time() { return bw.t0_; }
  bool warm_start() const { return bw.options_.warm_start; }
  bool halve_on_failure() const { return bw.options_.on_failure == BaraffWitkinOptions::OnFailure::HalveStep; }
  int max_halvings() const { return bw.options_.max_halvings; }
};

bool BaraffWitkin::attempt(Scene& scene, double h, StepStats& st, SolveReport& rep) {
  StepOps ops{*this, scene};
  return bw::attempt(ops, h, st, rep);
}

// The force each pinned vertex receives from its pin in this step: the constraint force
// r_i = (A dv - b)_i / h = (M dv / h - f_lin(t + h) - M g)_i (plus the damping terms of A, b),
// recorded for the pin groups' reactions in stats.csv.
void BaraffWitkin::record_pin_forces(Scene& scene, double h) {
  const State& s = scene.state;
  std::vector<double>& out = scene.pins.constraint_forces();
  if (out.size() != 3 * s.pin_list.size()) return;  // sized in prepare(); pins added later are not recorded
  const BsrPattern& P = *pattern_;
  const double* a = A_.values().data();
  // Matrix-free self-contact springs: their part of A dv (the step's contacts, if any).
  const bool springs = !edv_.empty() && !self_contact_->contacts().empty();
  if (springs) {
    std::fill(edv_.begin(), edv_.end(), 0.0);
    self_contact_->apply_add(dv_.data(), edv_.data(), 1.0);
  }
  for (std::size_t k = 0; k < s.pin_list.size(); ++k) {
    const Index i = s.pin_list[k];
    double r[3] = {0, 0, 0};
    if (springs)
      for (int c = 0; c < 3; ++c) r[c] = edv_[3 * static_cast<std::size_t>(i) + c];
    for (Index q = P.row_ptr[i]; q < P.row_ptr[i + 1]; ++q)
      kernels::mat3_mul_add(a + 9 * static_cast<std::size_t>(q), &dv_[3 * static_cast<std::size_t>(P.col[q])], r);
    const double* bi = &b_[3 * static_cast<std::size_t>(i)];
    for (int c = 0; c < 3; ++c) out[3 * k + c] = (r[c] - bi[c]) / h;
  }
  scene.pins.record_constraint_forces(t0_ + h);
}

void BaraffWitkin::advance(Scene& scene, double h, int depth, StepStats& st) {
  StepOps ops{*this, scene};
  bw::advance(ops, scene.state, h, depth, st, "baraff_witkin");
}

void BaraffWitkin::step(Scene& scene, double h) {
  if (n_ != scene.state.size() || !pattern_) prepare(scene, h);
  StepStats st;
  t0_ = scene.state.time;
  advance(scene, h, 0, st);
  finish_step(scene.state, h);
  if (self_contact_) st.self_contacts = self_contact_->stats().contacts;
  last_ = st;
}

// dv, the contact flags, the collider contacts' responses (warm_D_, as many as the flags), then
// the self-contact pairs' responses: their count and (four vertices, response) each. A state of
// the format before the responses (dv and flags only) is read with none.
std::vector<double> BaraffWitkin::restart_state() const {
  std::vector<double> s(dv_.begin(), dv_.end());
  for (char c : in_contact_) s.push_back(c ? 1.0 : 0.0);
  s.insert(s.end(), warm_D_.begin(), warm_D_.end());
  const auto none = std::vector<std::pair<std::array<Index, 4>, double>>{};
  const auto& pairs = self_contact_ ? self_contact_->warm_responses() : none;
  s.push_back(static_cast<double>(pairs.size()));
  for (const auto& [v, D] : pairs) {
    for (Index i : v) s.push_back(static_cast<double>(i));
    s.push_back(D);
  }
  return s;
}

bool BaraffWitkin::set_restart_state(const std::vector<double>& s) {
  const std::size_t head = dv_.size() + in_contact_.size();
  if (s.size() < head) return false;
  std::vector<std::pair<std::array<Index, 4>, double>> pairs;
  if (s.size() > head) {
    const std::size_t w = head + warm_D_.size();
    if (s.size() < w + 1) return false;
    const std::size_t m = static_cast<std::size_t>(s[w]);
    if (s.size() != w + 1 + 5 * m) return false;
    for (std::size_t k = 0; k < m; ++k) {
      const double* e = &s[w + 1 + 5 * k];
      pairs.push_back({{static_cast<Index>(e[0]), static_cast<Index>(e[1]), static_cast<Index>(e[2]),
                        static_cast<Index>(e[3])},
                       e[4]});
    }
    std::copy(s.begin() + static_cast<std::ptrdiff_t>(head), s.begin() + static_cast<std::ptrdiff_t>(w), warm_D_.begin());
  } else {
    std::fill(warm_D_.begin(), warm_D_.end(), 0.0);
  }
  std::copy(s.begin(), s.begin() + static_cast<std::ptrdiff_t>(dv_.size()), dv_.begin());
  for (std::size_t i = 0; i < in_contact_.size(); ++i) in_contact_[i] = s[dv_.size() + i] != 0.0;
  if (self_contact_) self_contact_->set_warm_responses(std::move(pairs));
  return true;
}

}  // namespace loom
