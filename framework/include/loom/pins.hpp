// Pins: kinematic boundary conditions. A pin group is a set of vertices whose motion is
// prescribed (fixed, or a RigidMotion: translate, rotate about an axis through a point,
// keyframes with linear or smooth interpolation), with the reaction force the group exerts
// on the cloth. Parsing, vertex selection and the per-step placement live here, so that
// every integrator honours pins through the same few calls:
//
//   explicit integrators   apply(state, t + h) at the end of the step (positions and
//                          velocities exactly the prescribed ones); RK4 also place() at each
//                          stage, so the forces of every stage see the prescribed pins;
//   baraff_witkin          write_dv(): dv = (p(t + h) - x0)/h - v0 on pinned DOFs, so that
//                          x1 = x0 + h v1 lands on p(t + h); then apply_positions(state, t + h)
//                          removes the rounding of x0 + h v1.
//
// The reaction of a group (docs/NUMERICS.md "Moving pins and reaction forces") is the force
// the pins exert on the cloth: r = sum_i (m_i a_i - f_i - m_i g) over the group's vertices,
// with a_i the prescribed acceleration and f_i the internal force at the frame's state, or,
// for baraff_witkin, the constraint force of the last solve ((A dv - b)_i / h), which the
// integrator records with record_constraint_forces().
#pragma once

#include <array>
#include <span>
#include <string>
#include <vector>

#include "loom/collider.hpp"
#include "loom/common.hpp"
#include "loom/mesh.hpp"
#include "loom/params.hpp"
#include "loom/state.hpp"

namespace loom {

class Material;

/// Vertices named by a scene entry shared by `pins` and `mass_scale`: a group name
/// (top_edge, ...), {group: name}, {vertices: [i, ...]}, or {box: {min: [..], max: [..]}}
/// (every vertex inside the closed axis-aligned box). Keys of a mapping entry other than
/// group / vertices / box are left for the caller. Throws InputError (file:line and fix)
/// for an unknown group, an index out of range, or a selection with no vertex.
std::vector<Index> select_vertices(const Mesh& mesh, const Params& entry);

struct PinGroup {
  std::string name;              ///< column prefix in stats.csv: pin_<name>_fx, ...
  std::vector<Index> vertices;   ///< the vertices this group owns (sorted, unique)
  std::vector<double> rest;      ///< their positions at t = 0 (3 per vertex)
  RigidMotion motion;            ///< Fixed: the vertices never move (bit for bit)
  Vec3 center{0, 0, 0};          ///< point the rotation axis passes through at t = 0
  bool moving() const { return motion.type != RigidMotion::Type::Fixed; }
};

class PinSet {
 public:
  bool empty() const { return groups_.empty(); }
  /// True when some group has a prescribed motion (not all pins fixed).
  bool moving() const { return moving_; }
  const std::vector<PinGroup>& groups() const { return groups_; }

  /// Parse the scene's `pins:` list, pin the vertices in `state` (inverse mass 0) and place
  /// moving groups at t = state.time. A vertex in two groups is an error when either group moves
  /// (it would follow two motions); between fixed groups the first one owns it.
  static PinSet parse(const Params& list, const Mesh& mesh, State& state);
  /// Add a group programmatically (tests, benches): pins its vertices, records their
  /// current positions as rest positions, places them at state.time.
  void add(PinGroup group, State& state);

  /// Prescribed position, velocity and acceleration of group vertex k at time t.
  void evaluate(const PinGroup& g, std::size_t k, double t, double* x, double* v, double* a) const;

  /// Moving groups: positions and velocities at time t written into x, v (3n arrays).
  /// Fixed pins are not touched. No allocation.
  void place(double t, double* x, double* v) const;
  void apply(State& s, double t) const { place(t, s.x.data(), s.v.data()); }
  /// Moving groups: positions only (baraff_witkin after x1 = x0 + h v1).
  void apply_positions(State& s, double t) const;
  /// baraff_witkin's prescribed velocity changes on pinned DOFs: -v0 for every vertex in
  /// s.pin_list, then (p(t1) - x0)/h - v0 for the vertices of moving groups.
  void write_dv(const State& s, double t1, double h, std::span<double> z) const;

  /// Constraint forces per vertex of s.pin_list (3 each), recorded by an implicit integrator
  /// at time t; reactions() uses them when t is the state's time.
  void record_constraint_forces(double t) { constraint_time_ = t; }
  std::vector<double>& constraint_forces() { return constraint_force_; }

  /// Reaction force of each group (3 per group, in group order) at the state's time.
  /// `work` is resized to 3n once and reused (no allocation after the first call).
  void reactions(const State& s, const Material& material, const std::array<double, 3>& gravity,
                 std::vector<double>& work, std::vector<double>& out) const;

  /// Header columns for stats.csv: ",pin_<name>_fx,pin_<name>_fy,pin_<name>_fz" per group.
  std::string csv_header() const;

 private:
  std::vector<PinGroup> groups_;
  bool moving_ = false;
  std::vector<double> constraint_force_;
  double constraint_time_ = -1e300;
};

}  // namespace loom
