// Coulomb friction of a collider contact inside the implicit (Baraff-Witkin) step, per vertex:
// a damper on the vertex's velocity relative to the surface in the tangent plane,
// f = -c P (v1 - v_s), P = I - n n^T, whose h c is chosen so that the friction impulse meets
// Coulomb's bound (coulomb_damping), corrected after a solve where the bound is missed (the
// vertex's response read from its row of A, its neighbours as solved: a block-Jacobi step) while
// the contacts miss their bounds in sum by more than kFrictionStopTolerance, the first damper
// warm-started from the response the contact showed in the step before (friction_response), and
// a vertex held by static friction finished after the last solve (docs/CONTACT.md, "Friction
// inside the solve"). Header-only and LOOM_HD: the CPU plugin (baraff_witkin.cpp, whose
// self-contacts use coulomb_damping too) and the CUDA backend run this one source. Templated
// on the scalar.
#pragma once

#include <cmath>

#include "loom/common.hpp"

namespace loom::kernels {

/// h c / D of a contact held by static friction: its tangential slip within the step is
/// about 1/(1 + this) of the one without friction (the finish removes the rest).
inline constexpr double kStickDamping = 1.0e4;
/// Relative miss of the Coulomb bound that makes a correction choose a damper again.
inline constexpr double kCoulombTolerance = 0.01;
/// Solves with dampers per step, at most (the first and the corrections).
inline constexpr int kFrictionSolves = 3;
/// The corrections stop (no further solve with dampers) once the contacts of each kind (the
/// collider contacts; the self-contact pairs) miss their Coulomb bounds, in sum, by at most this
/// fraction of the sum of their kinetic bounds mu_k J (FrictionTally::settled). A per-contact
/// criterion (every contact within kCoulombTolerance) is never met by hundreds of coupled
/// contacts within kFrictionSolves block-Jacobi corrections: each correction approaches the
/// bound from above (docs/CONTACT.md, "Corrections that stop"). Not looser: a layer sliding as
/// one on another (44 pairs sharing vertices) falls 4.8 % short of mu g h after its first solve,
/// and the Coulomb tests allow 3 %.
inline constexpr double kFrictionStopTolerance = 0.02;
/// With an iterative solver, the solves with dampers that a correction may still follow run
/// at this many times the scene's tolerance (they only size the dampers), and one solve at the
/// scene's tolerance ends the step (bw::friction_solves). Not looser: the corrections read the
/// small slip of held contacts from those solves, and at 1000 times the default tolerance the
/// step's solve error on the wool drape (BwTolerance.DefaultTolerance...) was 400 times its
/// bound; at 300 and 100 within it (docs/CONTACT.md, "Friction inside the solve").
inline constexpr double kFrictionToleranceScale = 100.0;

/// h c (kg) of a Coulomb friction damper f = -c P u inside the implicit step, for a contact
/// whose tangential speed without friction is len (m/s), answering a tangential impulse p
/// with the speed change p / D (D in kg: the mass of a vertex alone), normal impulse Jn
/// (N s): a contact that static friction holds (D len <= mu_s Jn) gets kStickDamping D and
/// stick = true; a sliding one the damper with which it loses exactly mu_k Jn / D of its speed:
/// h c = mu_k Jn D / (D len - mu_k Jn) (then the friction impulse h c |u_t(v1)| is mu_k Jn).
template <class T>
LOOM_HD inline T coulomb_damping(T len, T D, T mus_Jn, T muk_Jn, bool& stick) {
  const T hold = static_cast<T>(kStickDamping) * D;
  if (D * len <= mus_Jn) {
    stick = true;
    return hold;
  }
  stick = false;
  const T slide = muk_Jn * D / (D * len - muk_Jn);
  return slide < hold ? slide : hold;
}

/// The first damper of a contact whose response lies between D0 (kg; what coulomb_damping
/// would size it with: a lower bound, or the response it showed in the step before) and D1 (an
/// upper bound: its response with every other vertex fixed, read from the diagonal blocks of
/// A), tangential speed len without friction: held (kStickDamping D1, stick = true) only when
/// even D1 cannot exceed the static bound (D1 len <= mu_s Jn); sliding with D0's damper where D0
/// already slides (D0 len > mu_s Jn: exact for a layer sliding as one); else, where D0 would
/// hold it and D1 would not, the damper that leaves mu_k Jn for the response D1: its friction
/// impulse h c len D / (D + h c) grows with the response D, so for any D in [D0, D1] it stays
/// at or below mu_k Jn (coulomb_damping with D0 holds it, and where its response is nearer D1
/// the stick damper's impulse is about D len, up to D1 len / (mu_k Jn) times the bound).
template <class T>
LOOM_HD inline T bracketed_coulomb_damping(T len, T D0, T D1, T mus_Jn, T muk_Jn, bool& stick) {
  if (D1 < D0) D1 = D0;
  if (D1 * len <= mus_Jn) {
    stick = true;
    return static_cast<T>(kStickDamping) * D1;
  }
  stick = false;
  const T D = D0 * len > mus_Jn ? D0 : D1;
  const T slide = muk_Jn * D / (D * len - muk_Jn), hold = static_cast<T>(kStickDamping) * D;
  return slide < hold ? slide : hold;
}

/// The correction's new damper for a contact (a collider contact or a self-contact pair) that
/// missed its Coulomb bound, given its response D (kg) with its neighbours as solved and its slip
/// f (m/s) without its own damper: held (kStickDamping D) when D f <= mu_s J and it was not
/// released in this step, else the damper that leaves it mu_k J (at most the held one). Returns
/// false when nothing changes: it stays held, or it was let go but is too slow to slide (D f <=
/// mu_k J) and already has the stiffest damper (no further solve for it).
template <class T>
LOOM_HD inline bool resize_damper(T D, T f, T mus_Jn, T muk_Jn, bool released, bool was_stick, T hc_now, T& hc,
                                  bool& stick) {
  const T hold = static_cast<T>(kStickDamping) * D;
  stick = D * f <= mus_Jn && !released;
  if (was_stick && stick) return false;
  hc = hold;
  if (!stick && D * f > muk_Jn) {
    const T slide = muk_Jn * D / (D * f - muk_Jn);
    if (slide < hold) hc = slide;
  }
  return !(!stick && !was_stick && hc == hold && hc_now >= hold * (T(1) - static_cast<T>(kCoulombTolerance)));
}

/// One contact's miss of its Coulomb bound after a solve, friction impulse p (N s): a held
/// contact misses by max(0, p - mu_s J), a sliding one by |p - mu_k J|; `excess` gets the part
/// above the bound, max(0, p - bound).
template <class T>
LOOM_HD inline T coulomb_miss(T p, T mus_Jn, T muk_Jn, bool stick, T& excess) {
  const T bound = stick ? mus_Jn : muk_Jn;
  excess = p > bound ? p - bound : T(0);
  if (stick) return excess;
  return p > muk_Jn ? p - muk_Jn : muk_Jn - p;
}

/// The contacts' friction against their Coulomb bounds, summed over the contacts of one kind
/// after a solve with dampers: the misses (coulomb_miss), the parts above the bounds, and the
/// kinetic bounds mu_k J (N s).
template <class T>
struct FrictionTally {
  T miss = 0, excess = 0, bound = 0;
  int contacts = 0;
  LOOM_HD void add(T m, T e, T b) {
    miss += m;
    excess += e;
    bound += b;
    ++contacts;
  }
  /// Close enough to Coulomb's bounds to stop correcting (kFrictionStopTolerance).
  LOOM_HD bool settled() const { return miss <= static_cast<T>(kFrictionStopTolerance) * bound; }
  /// The excess over the bounds relative to their sum (0 without contacts).
  LOOM_HD T relative_excess() const { return bound > T(0) ? excess / bound : T(0); }
};

/// |v + dv - vs| in the tangent plane of the unit normal n (m/s); its vector in vt when given.
template <class T>
LOOM_HD inline T tangential_speed(const T* v, const T* dv, const T* vs, const T* n, T* vt = nullptr) {
  T vrel[3];
  for (int k = 0; k < 3; ++k) vrel[k] = v[k] + dv[k] - vs[k];
  const T vn = vrel[0] * n[0] + vrel[1] * n[1] + vrel[2] * n[2];
  T t[3];
  for (int k = 0; k < 3; ++k) t[k] = vrel[k] - vn * n[k];
  if (vt)
    for (int k = 0; k < 3; ++k) vt[k] = t[k];
  using std::sqrt;
  return sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
}

/// Adds the damper dhc P to the vertex's diagonal block (row-major 3x3) and its right-hand
/// side -dhc P (v0 - vs) to b (3 values), v0 the velocity at the step start.
template <class T>
LOOM_HD inline void add_tangential_damper(const T* v0, const T* vs, const T* n, T dhc, T* blk, T* b) {
  T w0[3];
  for (int k = 0; k < 3; ++k) w0[k] = v0[k] - vs[k];
  const T w0n = w0[0] * n[0] + w0[1] * n[1] + w0[2] * n[2];
  for (int r = 0; r < 3; ++r) {
    b[r] -= dhc * (w0[r] - w0n * n[r]);
    for (int q = 0; q < 3; ++q) blk[3 * r + q] += dhc * ((r == q ? T(1) : T(0)) - n[r] * n[q]);
  }
}

/// The friction state of one collider contact inside a step.
template <class T>
struct ColliderFrictionState {
  T hc = 0;      ///< h c of the damper (kg), 0 when none
  T len0 = 0;    ///< tangential relative speed of the solve without it (m/s)
  bool stick = false;  ///< held by static friction
  bool released = false;  ///< held earlier in this step and let go: slides until the step ends
};

/// The first damper of a contact in contact (not landing) whose last solve left the normal
/// impulse `impulse` (N s) > 0: len0 from v + dv, h c from coulomb_damping with the response
/// `mass` (the vertex's mass, or the response the contact showed in the step before:
/// collider_friction_response); added to blk and b. Returns false (and h c = 0) when the contact
/// gets no friction (no coefficient, or not pushing).
template <class T>
LOOM_HD inline bool start_collider_friction(const T* v0, const T* dv, const T* vs, const T* n, T mass, T mu_s, T mu_k,
                                            T impulse, T* blk, T* b, ColliderFrictionState<T>& fs) {
  fs.stick = false;
  fs.released = false;
  fs.hc = T(0);
  if ((mu_s <= T(0) && mu_k <= T(0)) || !(impulse > T(0))) return false;
  fs.len0 = tangential_speed(v0, dv, vs, n);
  fs.hc = coulomb_damping(fs.len0, mass, mu_s * impulse, mu_k * impulse, fs.stick);
  add_tangential_damper(v0, vs, n, fs.hc, blk, b);
  return true;
}

/// After a solve with the damper: where the friction impulse p = h c |v_t(v1)| misses the
/// Coulomb bound (a held vertex above mu_s J, a sliding one off mu_k J) by more than
/// kCoulombTolerance, the damper is chosen again for the vertex as that solve left its
/// neighbours (one block-Jacobi step of the contacts): its response along its slip direction t
/// is read from its row of A, D = t^T A_ii t / |t|^2 - h c (its mass and its stiffness to
/// neighbours that stay as solved; at least its mass), its slip without its own damper is
/// f = |v_t(v1)| + p / D, and coulomb_damping(f, D) holds it (D f <= mu_s J) or gives the damper
/// that leaves it mu_k J. A contact let go (held -> sliding) slides for the rest of the step:
/// it is not held again (no cycling). blk, b change by the difference. Returns whether it
/// changed (solve again).
///
/// (The rule before 2026-11-30 took D = p / (len0 - |v_t(v1)|), the response from the solve
/// without friction, where the neighbours moved freely: with the neighbours held it
/// underestimated the response, and the held/sliding split swung from solve to solve without
/// settling; docs/CONTACT.md.)
template <class T>
LOOM_HD inline bool correct_collider_friction(const T* v0, const T* dv, const T* vs, const T* n, T mass, T mu_s,
                                              T mu_k, T impulse_n, T* blk, T* b, ColliderFrictionState<T>& fs) {
  if (fs.hc == T(0)) return false;
  const T tol = static_cast<T>(kCoulombTolerance);
  T vt[3];
  const T l1 = tangential_speed(v0, dv, vs, n, vt);
  const T impulse = fs.hc * l1;
  const T ms = mu_s * impulse_n, mk = mu_k * impulse_n;
  const T miss = impulse > mk ? impulse - mk : mk - impulse;
  if (fs.stick ? impulse <= ms * (T(1) + tol) : miss <= tol * mk) return false;
  T D = mass;
  if (l1 > T(0)) {
    T q = 0;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) q += vt[r] * blk[3 * r + c] * vt[c];
    const T d = q / (l1 * l1) - fs.hc;
    if (d > D) D = d;
  }
  T hc;
  bool stick;
  if (!resize_damper(D, l1 + impulse / D, ms, mk, fs.released, fs.stick, fs.hc, hc, stick)) return false;
  add_tangential_damper(v0, vs, n, hc - fs.hc, blk, b);
  if (fs.stick && !stick) fs.released = true;
  fs.hc = hc;
  fs.stick = stick;
  return true;
}

/// After a solve with the damper: the contact's miss of its Coulomb bound (coulomb_miss; 0
/// without a damper), the part above it in `excess` and its kinetic bound mu_k J in `bound`.
template <class T>
LOOM_HD inline T collider_friction_miss(const T* v0, const T* dv, const T* vs, const T* n, T mu_s, T mu_k,
                                        T impulse_n, const ColliderFrictionState<T>& fs, T& excess, T& bound) {
  excess = bound = T(0);
  if (fs.hc == T(0)) return T(0);
  bound = mu_k * impulse_n;
  return coulomb_miss(fs.hc * tangential_speed(v0, dv, vs, n), mu_s * impulse_n, bound, fs.stick, excess);
}

/// A contact's response over the step just solved (kg): its friction impulse p over the slip it
/// took out of the solve without friction, p / (len0 - |u_t(v1)|), at least `floor` (its mass
/// or, for a pair, 1/W); 0 when it had no damper or its slip did not fall. The next step's
/// first damper of the same contact starts from it (a warm start: coulomb_damping(len0, D, ...)
/// then maps that step's frictionless slip to the friction impulse this step's cloth answered
/// with) instead of the mass, which is exact only for a vertex alone or a sheet sliding as one
/// (docs/CONTACT.md, "Corrections that stop").
template <class T>
LOOM_HD inline T friction_response(T hc, T len0, T l1, T floor) {
  const T p = hc * l1;
  if (!(hc > T(0)) || !(len0 > l1) || !(p > T(0))) return T(0);
  const T D = p / (len0 - l1);
  return D > floor ? D : floor;
}

/// A collider contact's friction_response after the last solve (before finish_collider_friction).
template <class T>
LOOM_HD inline T collider_friction_response(const T* v0, const T* dv, const T* vs, const T* n, T mass,
                                            const ColliderFrictionState<T>& fs) {
  if (fs.hc == T(0)) return T(0);
  return friction_response(fs.hc, fs.len0, tangential_speed(v0, dv, vs, n), mass);
}

/// After the last solve: a vertex held by static friction loses the tangential velocity the
/// finite damper leaves (about 1/kStickDamping of its slip without friction).
template <class T>
LOOM_HD inline void finish_collider_friction(const T* v0, T* dv, const T* vs, const T* n,
                                             const ColliderFrictionState<T>& fs) {
  if (!fs.stick) return;
  T vt[3];
  tangential_speed(v0, dv, vs, n, vt);
  for (int k = 0; k < 3; ++k) dv[k] -= vt[k];
}

}  // namespace loom::kernels
