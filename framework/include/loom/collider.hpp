// Analytic colliders (sphere, infinite plane) with rigid motion and Coulomb friction.
//
// Colliders are part of the framework rather than a plugin kind: they are a few analytic
// shapes that every integrator must honour in the same way (explicit integrators through
// resolve_contacts after each step, Baraff-Witkin through constraints in its filter), so
// one shared implementation keeps the contact rules identical across integrators.
// They exist only when a scene declares them.
#pragma once

#include <array>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "loom/bsr.hpp"
#include "loom/common.hpp"
#include "loom/kernels/contact.hpp"
#include "loom/params.hpp"
#include "loom/state.hpp"

namespace loom {

class MeshBody;

using Vec3 = std::array<double, 3>;

/// Rigid motion of a collider or a pin group: a reference point c(t) = c0 + d(t) and a
/// rotation R(t) by angle(t) about a fixed unit axis through c(t).
struct RigidMotion {
  enum class Type { Fixed, Translate, Rotate, Keyframes } type = Type::Fixed;
  /// Keyframes: Linear (constant velocity between keys) or Smooth (each segment eased by the
  /// quintic s(w) = 10w^3 - 15w^4 + 6w^5: velocity and acceleration vanish at every key, C2).
  enum class Interp { Linear, Smooth } interpolation = Interp::Linear;
  Vec3 velocity{0, 0, 0};          ///< Translate: dc/dt (m/s)
  Vec3 axis{0, 1, 0};              ///< Rotate/Keyframes: unit rotation axis
  double angular_velocity = 0;     ///< Rotate: rad/s
  struct Key {
    double t;
    Vec3 translate;
    double angle;
  };
  std::vector<Key> keys;           ///< Keyframes: sorted by t, interpolated in between, held outside

  Vec3 displacement(double t) const;     ///< d(t)
  double angle(double t) const;          ///< rotation angle at t
  Vec3 linear_velocity(double t) const;  ///< dd/dt
  double spin(double t) const;           ///< d angle/dt
  Vec3 linear_acceleration(double t) const;  ///< d^2 d/dt^2 (inside segments; 0 for linear keys)
  double spin_acceleration(double t) const;  ///< d^2 angle/dt^2
};

/// Parse a `motion:` mapping {type: fixed | translate | rotate | keyframes, ...} shared by
/// colliders and pins (InputError with file:line on bad input). Keys listed in `also_known`
/// are left for the caller (e.g. a pin group's rotation `center`).
/// A 3-vector scene key (finite numbers), or def when absent (an error when required).
Vec3 read_vec3(const Params& p, const std::string& key, const Vec3& def, bool required = false);

RigidMotion parse_rigid_motion(const Params& m, const std::vector<std::string>& also_known = {});

struct Collider {
  enum class Shape { Sphere, Plane, Mesh } shape = Shape::Plane;
  Vec3 point{0, 0, 0};     ///< sphere centre, a point on the plane, or the mesh's pivot (the reference point c0)
  Vec3 normal{0, 1, 0};    ///< plane normal at t = 0 (unit), pointing to the free side
  double radius = 0;       ///< sphere radius
  double thickness = 0;    ///< contact offset: vertices are kept this far outside the surface
  double mu_static = 0, mu_kinetic = 0;
  RigidMotion motion;
  std::string name;        ///< for messages
  /// Mesh: the body (positions at t = 0, BVH), shared by copies. Queries transform the point
  /// into the body frame (rigid motion) and back.
  std::shared_ptr<const MeshBody> body;

  struct Contact {
    double distance;   ///< signed distance to the offset surface (< 0: inside)
    Vec3 normal;       ///< outward unit normal
    Vec3 velocity;     ///< velocity of the surface at the contact point
  };
  /// The collider's placement at one time: computed once per step, then queried per vertex.
  struct Frame {
    Vec3 center;    ///< reference point c(t)
    Vec3 normal;    ///< plane normal at t
    Vec3 omega;     ///< angular velocity vector
    Vec3 vlin;      ///< linear velocity of the reference point
    double rot[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< mesh: rotation body -> world (row major)
  };
  Frame frame_at(double t) const;
  /// Signed distance, normal and surface velocity at position x for a placement.
  Contact query(const Frame& f, const double x[3]) const;
  /// The same for callers that need it only where the distance is below `cutoff` (>= 0): a
  /// result below cutoff is exact; a result >= cutoff is a lower bound (normal and velocity
  /// then unspecified). Mesh colliders answer far vertices cheaply (MeshBody::signed_distance
  /// with a cutoff; spheres and planes by a bound on the distance that needs no square root).
  Contact query(const Frame& f, const double x[3], double cutoff) const;
  /// Same, at time t (computes the frame: use frame_at + query in loops).
  Contact query(const double x[3], double t) const { return query(frame_at(t), x); }
  /// A sphere or plane at a placement as the contact kernel's plain data
  /// (loom/kernels/contact.hpp, shared with the CUDA backend). Not for meshes.
  kernels::ContactShape<double> contact_shape(const Frame& f) const;
};

/// All colliders of a scene.
class ColliderSet {
 public:
  bool empty() const { return colliders_.empty(); }
  std::size_t size() const { return colliders_.size(); }
  const std::vector<Collider>& colliders() const { return colliders_; }
  void add(const Collider& c) { colliders_.push_back(c); }

  /// Parse the scene's `colliders:` list (InputError with file:line on bad input). Mesh
  /// colliders' OBJ paths resolve against base_dir when relative.
  static ColliderSet parse(const Params& list, const std::string& base_dir = "");

  /// After an explicit step of size h ending at time t: vertices inside a collider are moved
  /// to its surface and their velocity relative to the surface loses its inward normal part,
  /// then Coulomb friction acts on the tangential part (static: stick if |v_t| <= mu_s * dv_n,
  /// kinetic: |v_t| reduced by mu_k * dv_n). The tangential velocity change is also applied to
  /// the position (h * dv_t), as if the step had moved with the corrected velocity, so that
  /// a sticking vertex does not creep. Pinned vertices are skipped. Never adds energy
  /// relative to the surface. Returns the number of vertices in contact.
  int resolve_contacts(State& s, double t, double h) const;

 private:
  int resolve_with_frames(State& s, const Collider::Frame* frames, double h) const;
  std::vector<Collider> colliders_;
};

}  // namespace loom
