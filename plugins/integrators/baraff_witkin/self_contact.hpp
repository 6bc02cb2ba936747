// Self-contacts of the cloth inside the Baraff-Witkin step (docs/CONTACT.md, "Self-contact in
// the implicit step"; NUMERICS.md 3.1 for the step itself).
//
// The step is first solved without self-contacts. Every vertex-triangle or edge-edge pair that
// is within the thickness at the step start, or that this solve brings within it (its gap
// linearised along the normal), becomes a stiff one-sided spring on its gap along the contact
// normal, and the step is solved again with the springs. The normal n and the weights w
// (barycentric) are frozen at the step start:
//   C(x) = n . sum_a w_a x_a - r,   E = k/2 C^2,   f_a = -k C w_a n,
//   df_a/dx_b = -k w_a w_b n n^T   (exact for this force; rank one, negative semidefinite),
// with k = kappa m_eff / h^2 (m_eff = 1 / sum_a w_a^2 / m_a, kappa = kStiffness) and the rest gap
// r = min(thickness, gap at the step start): a pair already closer than the thickness is
// kept from approaching but not pushed out (a push out within one step would leave its velocity,
// (thickness - gap)/h, in the cloth); the after-step response restores its gap gradually and
// without velocity (SelfCollision::resolve). Backward Euler
// then ends the step with C(x1) = C_pred / (1 + kappa) (C_pred: the gap error the step would
// have without the spring): a pair approaching the thickness closes the gap within the step and
// stops there. A = ... - h^2 df/dx stays symmetric positive definite: each contact adds
// h^2 k (w w^T) (x) (n n^T), positive semidefinite. The blocks (a, b) of a contact couple
// vertices the material does not, so the integrator extends its BSR pattern with them (and a
// one-ring around, so that a sliding contact keeps finding its blocks) when a contact needs one
// it lacks. A spring that would pull at the end of the step (C(x1) > 0) is released and the
// step solved again, as Baraff & Witkin release collider constraints. Coulomb friction
// (self_collision.friction) acts after the solve on pairs already within the thickness at
// the step start, bounded by the spring's normal impulse h k max(0, -C(x1)).
#pragma once

#include <array>
#include <utility>
#include <vector>

#include "loom/bsr.hpp"
#include "loom/common.hpp"
#include "loom/kernels/friction.hpp"
#include "loom/linear_solver.hpp"
#include "loom/mesh.hpp"
#include "loom/self_collision.hpp"
#include "loom/state.hpp"

namespace loom {

/// CPU time of the calling thread (s), for the counters of one-thread probes.
double thread_seconds();

/// h c of a Coulomb friction damper: loom/kernels/friction.hpp (one source with the colliders'
/// friction and the CUDA backend).
using kernels::coulomb_damping;

/// As an ExtraOperator (matrix-free, when the scene's solver supports it: filtered_pcg with
/// any preconditioner, sa_amg included), the springs' term E = h^2 sum_c k_c (w w^T) (x) (n n^T) is
/// applied inside the solver's product and its diagonal blocks join the preconditioner's, so
/// the integrator's pattern stays the material's and nothing allocates while contacts come
/// and go; only b carries the springs' right-hand side. Otherwise the blocks are assembled
/// into A, whose pattern grows to hold them (reserve_pairs, bind).
class ImplicitSelfContact final : public ExtraOperator {
 public:
  /// kappa: the spring stiffness relative to the pair's effective mass over h^2. The gap error
  /// a step leaves is 1/(1 + kappa) of the one it would have without the spring.
  static constexpr double kStiffness = 100.0;
  /// A pair is in contact (friction acts) when its gap at the step start is below the thickness
  /// times (1 + this): layers resting on each other hold pairs at and just above the thickness
  /// (the after-step response restores gaps towards it, and neighbouring elements of the one
  /// under a vertex are a little farther), and those carry weight too.
  static constexpr double kTouchingTolerance = 0.05;

  struct Contact {
    bool vt;           ///< vertex-triangle (else edge-edge)
    Index v[4];
    double w[4];
    double n[3];
    double gap0;       ///< n . sum w x0: the distance at the step start
    double rest;       ///< the spring's rest gap: the thickness, or gap0 when already closer
    double k;          ///< spring stiffness (N/m)
    double c1;         ///< C(x1) after the solve (m)
    double W;          ///< sum_a w_a^2 / m_a
    double lambda;     ///< accumulated impulse of stop_approach (N s)
    bool touching;     ///< within (1 + kTouchingTolerance) thickness at the step start: friction acts
    bool stick;        ///< implicit friction: held by static friction (add_friction)
    bool released;     ///< implicit friction: held earlier in this step and let go: slides until it ends
    double fr;         ///< implicit friction: h c of the tangential damper (kg), 0 when none
    double len0;       ///< implicit friction: |u_t| of the solve without the damper (m/s)
    double jn;         ///< implicit friction: the spring's normal impulse h k (-C(x1)) (N s)
    double stiff;      ///< implicit friction: its response with the other vertices fixed (add_friction; kg)
    Index blk[16];     ///< positions of blocks (v[a], v[b]) in the pattern, a-major
  };
  struct Stats {
    Index contacts = 0;   ///< springs in the last solve
    Index released = 0;   ///< springs released after the first solve (pulling)
    Index friction = 0;   ///< pairs that received a friction impulse
    int stop_passes = 0;  ///< projected Gauss-Seidel passes of stop_approach
    int solves = 0;       ///< solves with springs in this step (the first and those after releases)
    int iterations = 0;   ///< linear iterations of those solves
    Index pairs = 0;             ///< pairs that SelfCollision::proximity_pairs returned to find()
    // CPU seconds of the calling thread (thread_seconds()), for one-thread probes:
    double pairs_seconds = 0;    ///< find(): SelfCollision::proximity_pairs
    double find_seconds = 0;     ///< find(): the pairs and the contacts
    double pattern_seconds = 0;  ///< extending the pattern (rebuild, bind, analyse), when it happened
    double solve_seconds = 0;    ///< the solves with springs (assembly of the terms included)
  };

  /// Vertex one-rings from the mesh, the thickness and friction; work arrays sized.
  void prepare(const Mesh& mesh, double thickness, double friction);
  /// Matrix-free (true): add_terms and release change b only, and the solver applies the
  /// springs' matrix term through apply_add / add_diagonal; find() needs no pattern blocks.
  void set_matrix_free(bool on) { matrix_free_ = on; }
  bool matrix_free() const { return matrix_free_; }
  /// y += scale E x, E = h^2 sum over the current contacts of k (w w^T) (x) (n n^T), h the
  /// step of the last find(). Serial: about 30 flops per contact.
  void apply_add(const double* x, double* y, double scale) const override;
  /// D_a += h^2 k w_a^2 n n^T for every vertex a of every contact.
  void add_diagonal(double* D) const override;

  /// Re-solves after releasing pulling springs, at most.
  static constexpr int kMaxReleaseSolves = 3;
  /// With an iterative solver, the solves with springs that decide the releases (all but the
  /// last) run at this many times the scene's tolerance (1e-5 -> 1e-2 by default), and one
  /// solve at the scene's tolerance, warm-started from them, ends the step. One-thread probe
  /// of BM_BwStepSplit/128: spring iterations per step 405 -> 141 (docs/CONTACT.md).
  static constexpr double kReleaseToleranceScale = 1000.0;

  /// Contacts for a step of size h from s, given the step's velocity change dv solved without
  /// them: pairs within the thickness at s.x, or whose gap (linearised along their normal)
  /// falls below it at s.x + h (v + dv). Returns whether there is any. When blocks_complete()
  /// is false the pattern P lacks a block they need: rebuild it with reserve_pairs() and bind().
  bool find(SelfCollision& sc, const State& s, const std::vector<double>& dv, double h, const BsrPattern& P);
  bool blocks_complete() const { return complete_; }
  /// The contact blocks the pattern should hold (beyond the material's): the current contacts'
  /// pairs and their one-ring, added to the pairs kept from earlier extensions; when the union
  /// outnumbers `limit`, only the current contacts' (a restart, counted by restarts()).
  const std::vector<std::array<Index, 2>>& reserve_pairs(std::size_t limit);
  int restarts() const { return restarts_; }
  /// Block positions of the contacts and the blocks of P the material does not have.
  /// Returns whether P holds every block the contacts need.
  bool bind(const BsrPattern& P, const BsrPattern& material);
  /// Zero the non-material blocks of a Jacobian (the material writes only its own).
  void zero_extra_blocks(BsrMatrix& J) const;
  /// The Kang-Cho Laplacian damper of the assembly kernel couples every off-diagonal block of
  /// the pattern; remove it from the non-material blocks (hcd = h c_d).
  void undo_laplacian(BsrMatrix& A, std::vector<double>& b, const std::vector<double>& v, double hcd) const;
  /// A += sign h^2 k (w w^T) (x) n n^T,  b += sign (-h k w_a (C0 + h n . sum w v0) n) for contact c.
  void add_term(const Contact& c, BsrMatrix& A, std::vector<double>& b, const std::vector<double>& v, double h,
                double sign) const;
  void add_terms(BsrMatrix& A, std::vector<double>& b, const std::vector<double>& v, double h) const;
  /// After a solve: C(x1) of each contact; springs that pull (C(x1) > 0) are removed from A, b
  /// and the list. Returns whether any was.
  bool release(BsrMatrix& A, std::vector<double>& b, const std::vector<double>& v, const std::vector<double>& dv,
               double h);
  /// Coulomb friction on touching pairs: changes dv.
  void apply_friction(const State& s, std::vector<double>& dv, double h);
  /// Coulomb friction inside the solve (BaraffWitkinOptions::implicit_friction): for every
  /// touching pair whose spring pushes after the last solve (C(x1) < 0, normal impulse
  /// J = h k (-C(x1))), a damper on the relative tangential velocity u = sum_a w_a v_a,
  /// f_a = -c w_a P u (P = I - n n^T), is added to A (assembled, or through apply_add when
  /// matrix-free) and b; h c from kernels::bracketed_coulomb_damping with the pair's
  /// first_response (1/W, W = sum w_a^2 / m_a, or the response it showed in the step before) and
  /// its response with the other vertices fixed (as correct_friction reads it, before any
  /// pair's damper), and its |u_t| in the last solve: held only when even the stiffer response
  /// cannot exceed mu J (before 2026-11-30: held when the first_response could not, which let a
  /// new pair the cloth holds stiffly start with a friction impulse up to 20 times mu J;
  /// docs/CONTACT.md, "A first damper that cannot exceed the bound"). Implicit damping can only take energy out
  /// of the step, and the cloth around the pair sees the friction in the same solve. Returns
  /// whether any pair got a damper.
  bool add_friction(const State& s, BsrMatrix& A, std::vector<double>& b, const std::vector<double>& dv, double h);
  /// After a solve with the dampers: each pair's friction impulse p = h c |u_t(v1)| against the
  /// Coulomb bound; where it misses it by more than kCoulombTolerance, h c is chosen again for
  /// the pair as that solve left the other vertices (a block-Jacobi step, as
  /// kernels::correct_collider_friction): a tangential impulse p along t moves vertex a by
  /// w_a p t / K_a, K_a = t^T A_aa t / |t|^2 less the pair's own damper's share h c w_a^2 (at
  /// least the vertex's mass; matrix-free, A_aa plus the self-contact terms' diagonal blocks,
  /// add_diagonal), so the pair's response is D = 1 / sum_a w_a^2 / K_a (pinned vertices: no term); its
  /// slip without its own damper f = |u_t(v1)| + p / D; held when D f <= mu J and not let go
  /// earlier in the step, else the damper that leaves mu J. A pair let go (held -> sliding)
  /// slides for the rest of the step. A, b changed by the difference. Returns whether any
  /// damper changed (solve again). (Before 2026-11-30: D = p / (len0 - |u_t(v1)|), the response
  /// of the solve without friction; docs/CONTACT.md, "A correction that converges".)
  bool correct_friction(const State& s, BsrMatrix& A, std::vector<double>& b, const std::vector<double>& dv);
  /// The response a pair's first damper is sized with: the one it showed in the last step when
  /// it was a pair with friction then (same four vertices), else 1/W (exact for a layer sliding
  /// as one).
  double first_response(const Contact& c) const;
  /// The last step's pair responses (restart state): (four vertices, response) each.
  const std::vector<std::pair<std::array<Index, 4>, double>>& warm_responses() const { return warm_; }
  void set_warm_responses(std::vector<std::pair<std::array<Index, 4>, double>> w) { warm_ = std::move(w); }
  /// A step without pairs to add friction to: the next step starts from 1/W.
  void forget_warm_responses() { warm_.clear(); }
  /// After a solve with the dampers: the pairs' friction h c |u_t(v1)| against their Coulomb
  /// bounds mu J, summed (kernels::FrictionTally; correct_friction is skipped once settled()).
  kernels::FrictionTally<double> friction_tally(const State& s, const std::vector<double>& dv) const;
  /// After the last solve: the pairs held by static friction lose the relative tangential
  /// velocity the finite damper leaves (about 1/kStickDamping of it), within mu J W.
  void finish_friction(const State& s, std::vector<double>& dv);
  /// The step is over: the dampers leave the operator (apply_add, add_diagonal: the springs' term again).
  void clear_friction() {
    for (Contact& c : contacts_) c.fr = 0;
  }
  /// The friction constants (loom/kernels/friction.hpp): h c / D of a held contact, the
  /// relative miss of the Coulomb bound that makes correct_friction choose a damper again, and
  /// the solves with dampers per step, at most.
  static constexpr double kStickDamping = kernels::kStickDamping;
  static constexpr double kCoulombTolerance = kernels::kCoulombTolerance;
  static constexpr int kFrictionSolves = kernels::kFrictionSolves;
  /// The friction solves' tolerance scale with an iterative solver (loom/kernels/friction.hpp).
  static constexpr double kFrictionToleranceScale = kernels::kFrictionToleranceScale;
  /// After the step (x1 = x0 + h v1 has landed the approaching pairs at the thickness, with
  /// v1 still their approach velocity): make every contact inelastic, relative normal velocity
  /// >= 0, by the smallest mass-weighted velocity change (projected Gauss-Seidel on the
  /// contacts' accumulated impulses, which stay >= 0; positions untouched). As the landing
  /// fix for colliders (BaraffWitkin::stop_landed). Returns the passes it took.
  int stop_approach(State& s);

  const std::vector<Contact>& contacts() const { return contacts_; }
  const Stats& stats() const { return stats_; }
  Stats& mutable_stats() { return stats_; }
  double thickness() const { return thickness_; }
  /// The contact force on every vertex at positions x (3n, zero first), for the spring model
  /// of the current contacts: f_a = -k C(x) w_a n (tests compare its finite differences with
  /// the Jacobian blocks).
  void forces(const std::vector<double>& x, std::vector<double>& f) const;

 private:
  double thickness_ = 0, friction_ = 0;
  double h_ = 0;                              ///< the step of the last find()
  bool matrix_free_ = false;
  std::vector<Index> ring_ptr_, ring_;        ///< vertex one-rings (CSR, the vertex included)
  std::vector<ProximityPair> pairs_;
  std::vector<double> d_;                     ///< predicted displacement
  /// The pairs' responses in the last step (kernels::friction_response), by their vertices,
  /// sorted: a pair found again starts its first damper from it (first_response).
  std::vector<std::pair<std::array<Index, 4>, double>> warm_;
  std::vector<double> diag_;                  ///< add_friction / correct_friction, matrix-free: the self-contact terms' diagonal blocks (9 per vertex)
  /// Matrix-free, A holds no self-contact term: diag_ gets their diagonal blocks (add_diagonal,
  /// the contacts' vertices zeroed first) and is returned, so that both forms read the same
  /// response beside A; assembled, nullptr.
  double* matrix_free_diagonal();
  std::vector<Contact> contacts_;
  std::vector<std::array<Index, 2>> reserve_, fresh_;
  std::vector<std::array<Index, 3>> extra_;   ///< (block position, row, column) of non-material blocks
  Stats stats_;
  bool complete_ = true;
  int restarts_ = 0;
};

}  // namespace loom
