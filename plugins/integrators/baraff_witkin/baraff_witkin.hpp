// baraff_witkin: one linearised backward-Euler step per call (Baraff & Witkin 1998,
// NUMERICS.md 3.1), with the consistent Kang-Cho damping of 3.2, optional Rayleigh damping,
// and the constraint filter S / prescribed velocity changes z for pins and plane
// constraints, solved by the scene's LinearSolver.
//
//   A = (1 + h alpha) M - h df/dv - (h^2 + h beta) df/dx + h c_d L
//   b = h ( f0 - alpha M v0 + (h + beta) df/dx v0 - c_d L v0 ),   f0 = f(x0, v0) + M g
//   v1 = v0 + dv,   x1 = x0 + h v1
#pragma once

#include <array>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "loom/bsr.hpp"
#include "loom/kernels/friction.hpp"
#include "loom/integrator.hpp"
#include "loom/param_spec.hpp"
#include "loom/params.hpp"
#include "self_contact.hpp"

namespace loom {

struct BaraffWitkinOptions {
  double kang_cho_damping = 0;   ///< c_d (N s/m) of the graph-Laplacian damper
  double rayleigh_alpha = 0;     ///< mass-proportional damping (1/s)
  double rayleigh_beta = 0;      ///< stiffness-proportional damping (s)
  enum class OnFailure { Stop, HalveStep } on_failure = OnFailure::Stop;
  int max_halvings = 3;          ///< nesting depth of halve_step retries
  bool warm_start = true;        ///< start each solve from the previous step's dv
  bool implicit_self_contact = true;  ///< self-contacts as springs in the solve (self_contact.hpp)
  /// Coulomb friction of collider contacts and self-contact springs as tangential dampers in
  /// one more solve (add_collider_friction, ImplicitSelfContact::add_friction) instead of a
  /// velocity correction after the solve (docs/CONTACT.md, "Friction inside the solve").
  bool implicit_friction = true;
};

/// The keys of baraff_witkin (cpu and cuda): kang_cho_damping, rayleigh {alpha, beta},
/// on_solver_failure (stop | halve_step), max_halvings, warm_start, implicit_self_contact
/// (cpu); precision and host_sync_every for the cuda backend.
const ParamSpec& baraff_witkin_spec();
/// Reads the keys the cpu and cuda variants share, through baraff_witkin_spec().
BaraffWitkinOptions parse_baraff_witkin_options(const Params& p, const std::string& backend = "cpu");

class BaraffWitkin final : public Integrator {
 public:
  /// Extra constraints, called at the start of every solve after the pins are in place:
  /// add constraints to S (Filter::constrain_direction / constrain_all) and write the
  /// prescribed velocity changes of the constrained DOFs into z (zero elsewhere), so that
  /// (I - S) z = z. h is the (sub)step being taken.
  using ConstraintHook = std::function<void(const State& state, double h, Filter& S, std::span<double> z)>;

  explicit BaraffWitkin(BaraffWitkinOptions options = {});
  std::string name() const override { return "baraff_witkin"; }
  IntegratorNeeds needs() const override { return {false, true, true}; }
  void prepare(Scene& scene, double h) override;
  void step(Scene& scene, double h) override;
  StepStats last_step() const override { return last_; }
  /// Contacts with the scene's colliders become constraints of the filter (see contacts below).
  bool handles_contacts() const override { return true; }
  /// The warm start dv, the per-vertex contact flags and the contacts' friction responses of
  /// the last step (the next first dampers start from them): loom run --resume restarts exactly.
  std::vector<double> restart_state() const override;
  bool set_restart_state(const std::vector<double>& s) override;
  /// Vertices constrained by a collider in the last step (after releases).
  int contact_count() const { return static_cast<int>(contacts_.size()); }

  void set_constraint_hook(ConstraintHook hook) { hook_ = std::move(hook); }
  const BaraffWitkinOptions& options() const { return options_; }
  const BsrPattern& pattern() const { return *pattern_; }
  const BsrMatrix& system_matrix() const { return A_; }
  std::span<const double> rhs() const { return b_; }
  const Filter& filter() const { return S_; }
  /// Self-contact springs of the last solve (null unless the scene has self_collision and
  /// implicit_self_contact is on), and how often the pattern was extended for them.
  const ImplicitSelfContact* self_contact() const { return self_contact_.get(); }
  int pattern_rebuilds() const { return pattern_rebuilds_; }
  /// Solves with friction dampers since prepare() (implicit_friction).
  long long friction_solves() const { return friction_solves_; }
  /// The last step's friction against Coulomb's bounds after its last solve with dampers
  /// (implicit_friction; empty when it had none): the collider contacts and the self-contact pairs.
  const kernels::FrictionTally<double>& collider_friction() const { return collider_tally_; }
  const kernels::FrictionTally<double>& pair_friction() const { return pair_tally_; }
  /// Whether the self-contact springs are applied matrix-free by the solver (it supports an
  /// ExtraOperator: filtered_pcg on the CPU, every preconditioner); else they are assembled into A.
  bool self_contact_matrix_free() const { return self_contact_ && self_contact_->matrix_free(); }

 private:
  struct StepOps;  // the operations of the shared step skeleton (bw_step.hpp)
  bool attempt(Scene& scene, double h, StepStats& st, SolveReport& rep);
  void advance(Scene& scene, double h, int depth, StepStats& st);
  void assemble(const Scene& scene, double h);
  void set_constraints(const Scene& scene, double h);
  bool release_pulling_contacts(const Scene& scene, double h);
  void apply_friction(const Scene& scene);
  bool add_collider_friction(const Scene& scene);
  bool correct_collider_friction(const Scene& scene);
  void finish_collider_friction(const Scene& scene);
  kernels::FrictionTally<double> collider_friction_tally(const Scene& scene) const;
  struct Contact;
  double* diagonal_block(Index i);  ///< A_'s block (i, i)
  void project_positions(Scene& scene, double t);
  void record_pin_forces(Scene& scene, double h);
  void stop_landed(Scene& scene);
  void rebuild_pattern(Scene& scene);

  /// A vertex constrained by a collider at the end of the previous step, or within this
  /// distance (m) of a collider's offset surface (or inside) at the start of a step, is in
  /// contact (friction acts); one farther out but predicted to reach it is landing. (The
  /// first condition keeps a vertex sliding over a curved surface in contact: a step along
  /// the tangent plane ends it a little outside a convex surface.)
  static constexpr double kContactTolerance = 1e-9;
  /// Collider queries in set_constraints: exact below this distance (m), a lower bound above.
  static constexpr double kQueryCutoff = 1e-6;

  // One contact per vertex (the deepest collider): Baraff & Witkin's 2-DOF constraint.
  struct Contact {
    Index vertex;
    double normal[3];
    double surface_velocity[3];
    double mu_static, mu_kinetic;
    double dvn;      // prescribed normal velocity change (z = dvn * normal)
    double impulse;  // normal constraint impulse (A dv - b).n after the solve (>= 0 when pushing)
    bool landing;    // outside the surface at the step start: lands at its end, no friction
    kernels::ColliderFrictionState<double> fr;  // implicit friction: the damper (h c 0 when none)
  };
  std::vector<Contact> contacts_;   // capacity reserved in prepare()
  std::vector<char> in_contact_;    // per vertex: constrained by a collider at the end of the last step
  std::vector<Collider::Frame> frames0_, frames1_;  // collider placements at step start / end
  BaraffWitkinOptions options_;
  ConstraintHook hook_;
  std::unique_ptr<BsrPattern> pattern_;
  std::unique_ptr<ImplicitSelfContact> self_contact_;
  BsrPattern material_pattern_;                      // the material's blocks (pattern_ may hold more)
  std::vector<std::array<Index, 2>> material_pairs_, pattern_pairs_;
  int pattern_rebuilds_ = 0;
  long long friction_solves_ = 0;
  kernels::FrictionTally<double> collider_tally_, pair_tally_;
  // Per vertex: the response its collider contact showed in the last step (kg; 0 when none):
  // the next step's first damper starts from it (kernels::collider_friction_response).
  std::vector<double> warm_D_;
  BsrMatrix dfdx_, dfdv_, A_;
  Filter S_;
  std::vector<double> degree_;           // graph-Laplacian diagonal n_i
  std::vector<double> f_, b_, z_, dv_;
  std::vector<double> edv_;              // E dv of matrix-free self-contacts (pin forces)
  Index n_ = -1;
  double t0_ = 0;                        // start time of the (sub)step being solved
  StepStats last_;
};

}  // namespace loom
