// Parsing of a RigidMotion (`motion:` of colliders and pin groups).
#include <cmath>
#include <string>

#include "loom/collider.hpp"
#include "loom/section_specs.hpp"

namespace loom {

Vec3 read_vec3(const Params& p, const std::string& key, const Vec3& def, bool required) {
  Params c = p.child(key);
  if (!c.valid()) {
    if (required) p.fail("missing '" + key + "' (a list of 3 numbers).");
    return def;
  }
  const auto v = c.as_doubles();
  if (v.size() != 3) c.fail("needs 3 numbers, e.g. [0, 1, 0].");
  for (double x : v)
    if (!std::isfinite(x)) c.fail("components must be finite numbers (got NaN or Inf).");
  return {v[0], v[1], v[2]};
}

namespace {

Vec3 motion_axis(const Params& m) {
  const Vec3 a = read_vec3(m, "axis", {0, 1, 0}, false);
  const double len = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  if (!(len > 1e-12)) m.child("axis").fail("must be a non-zero vector.");
  return {a[0] / len, a[1] / len, a[2] / len};
}

}  // namespace

RigidMotion parse_rigid_motion(const Params& m, const std::vector<std::string>& also_known) {
  RigidMotion mo;
  if (!m.is_map()) m.fail("motion is a mapping with 'type': fixed, translate, rotate or keyframes.");
  const std::string mt = m.get_choice("type", "fixed", {"fixed", "translate", "rotate", "keyframes"});
  if (mt == "translate") {
    mo.type = RigidMotion::Type::Translate;
    mo.velocity = read_vec3(m, "velocity", {0, 0, 0}, true);
  } else if (mt == "rotate") {
    mo.type = RigidMotion::Type::Rotate;
    mo.axis = motion_axis(m);
    mo.angular_velocity = m.get("angular_velocity", 0.0);
    if (!std::isfinite(mo.angular_velocity)) m.child("angular_velocity").fail("must be a finite number (rad/s).");
  } else if (mt == "keyframes") {
    mo.type = RigidMotion::Type::Keyframes;
    mo.axis = motion_axis(m);
    mo.interpolation = m.get_choice("interpolation", "linear", {"linear", "smooth"}) == "smooth"
                           ? RigidMotion::Interp::Smooth
                           : RigidMotion::Interp::Linear;
    Params keys = m.child("keys");
    if (!keys.is_sequence() || keys.size() == 0)
      m.fail("keyframes need 'keys': a list of {t, translate: [x,y,z], angle} sorted by t.");
    for (std::size_t q = 0; q < keys.size(); ++q) {
      const Params kp = with_section_spec(keys.at(q), "motion_keys");
      if (!kp.is_map()) kp.fail("a key is a mapping {t: seconds, translate: [x, y, z], angle: radians}.");
      RigidMotion::Key key{kp.require_double("t"), read_vec3(kp, "translate", {0, 0, 0}, false), kp.get("angle", 0.0)};
      if (!std::isfinite(key.t) || !std::isfinite(key.angle)) kp.fail("t and angle must be finite numbers.");
      if (!mo.keys.empty() && !(key.t > mo.keys.back().t))
        kp.child("t").fail("keyframe times must increase (t = " + std::to_string(key.t) + " after t = " +
                           std::to_string(mo.keys.back().t) + "). Fix: list the keys in time order.");
      kp.check_unused();
      mo.keys.push_back(key);
    }
  }
  m.check_unused(also_known);
  return mo;
}

}  // namespace loom
