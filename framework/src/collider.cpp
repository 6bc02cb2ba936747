#include "loom/collider.hpp"
#include "loom/section_specs.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "loom/mesh_collider.hpp"

namespace loom {

namespace {

Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3 add(const Vec3& a, const Vec3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
Vec3 scale(const Vec3& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double norm(const Vec3& a) { return std::sqrt(dot(a, a)); }

// Rodrigues rotation of v by angle about unit axis k.
Vec3 rotate(const Vec3& v, const Vec3& k, double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  const Vec3 kxv = cross(k, v);
  const double kv = dot(k, v);
  return {v[0] * c + kxv[0] * s + k[0] * kv * (1 - c), v[1] * c + kxv[1] * s + k[1] * kv * (1 - c),
          v[2] * c + kxv[2] * s + k[2] * kv * (1 - c)};
}

// Index of the keyframe interval containing t and the interpolation weight.
std::pair<std::size_t, double> locate(const std::vector<RigidMotion::Key>& keys, double t) {
  if (keys.size() == 1 || t <= keys.front().t) return {0, 0.0};
  if (t >= keys.back().t) return {keys.size() - 2, 1.0};
  std::size_t k = 0;
  while (k + 2 < keys.size() && keys[k + 1].t <= t) ++k;
  return {k, (t - keys[k].t) / (keys[k + 1].t - keys[k].t)};
}

// Segment shape: weight s(w), ds/dw and d2s/dw2 for linear or smooth (quintic) keys.
struct Ease {
  double s, ds, dds;
};
Ease ease(RigidMotion::Interp in, double w) {
  if (in == RigidMotion::Interp::Linear) return {w, 1.0, 0.0};
  const double w2 = w * w;
  return {w2 * w * (10.0 - 15.0 * w + 6.0 * w2), 30.0 * w2 * (1.0 - w) * (1.0 - w),
          60.0 * w * (1.0 - w) * (1.0 - 2.0 * w)};
}

}  // namespace

Vec3 RigidMotion::displacement(double t) const {
  switch (type) {
    case Type::Translate: return scale(velocity, t);
    case Type::Keyframes: {
      if (keys.size() == 1) return keys[0].translate;
      const auto [k, w] = locate(keys, t);
      const double s = ease(interpolation, w).s;
      return add(scale(keys[k].translate, 1 - s), scale(keys[k + 1].translate, s));
    }
    default: return {0, 0, 0};
  }
}

double RigidMotion::angle(double t) const {
  switch (type) {
    case Type::Rotate: return angular_velocity * t;
    case Type::Keyframes: {
      if (keys.size() == 1) return keys[0].angle;
      const auto [k, w] = locate(keys, t);
      const double s = ease(interpolation, w).s;
      return (1 - s) * keys[k].angle + s * keys[k + 1].angle;
    }
    default: return 0.0;
  }
}

Vec3 RigidMotion::linear_velocity(double t) const {
  switch (type) {
    case Type::Translate: return velocity;
    case Type::Keyframes: {
      if (keys.size() < 2 || t < keys.front().t || t >= keys.back().t) return {0, 0, 0};
      const auto [k, w] = locate(keys, t);
      const double T = keys[k + 1].t - keys[k].t;
      return scale(sub(keys[k + 1].translate, keys[k].translate), ease(interpolation, w).ds / T);
    }
    default: return {0, 0, 0};
  }
}

double RigidMotion::spin(double t) const {
  switch (type) {
    case Type::Rotate: return angular_velocity;
    case Type::Keyframes: {
      if (keys.size() < 2 || t < keys.front().t || t >= keys.back().t) return 0.0;
      const auto [k, w] = locate(keys, t);
      const double T = keys[k + 1].t - keys[k].t;
      return (keys[k + 1].angle - keys[k].angle) * ease(interpolation, w).ds / T;
    }
    default: return 0.0;
  }
}

Vec3 RigidMotion::linear_acceleration(double t) const {
  if (type != Type::Keyframes || keys.size() < 2 || t < keys.front().t || t >= keys.back().t) return {0, 0, 0};
  const auto [k, w] = locate(keys, t);
  const double T = keys[k + 1].t - keys[k].t;
  return scale(sub(keys[k + 1].translate, keys[k].translate), ease(interpolation, w).dds / (T * T));
}

double RigidMotion::spin_acceleration(double t) const {
  if (type != Type::Keyframes || keys.size() < 2 || t < keys.front().t || t >= keys.back().t) return 0.0;
  const auto [k, w] = locate(keys, t);
  const double T = keys[k + 1].t - keys[k].t;
  return (keys[k + 1].angle - keys[k].angle) * ease(interpolation, w).dds / (T * T);
}

Collider::Frame Collider::frame_at(double t) const {
  Frame f;
  f.center = add(point, motion.displacement(t));
  f.omega = scale(motion.axis, motion.spin(t));
  f.vlin = motion.linear_velocity(t);
  const double angle = motion.angle(t);
  f.normal = shape == Shape::Plane ? rotate(normal, motion.axis, angle) : normal;
  if (shape == Shape::Mesh && angle != 0.0) {
    // Columns: the rotated unit vectors.
    for (int c = 0; c < 3; ++c) {
      Vec3 e{0, 0, 0};
      e[c] = 1;
      const Vec3 r = rotate(e, motion.axis, angle);
      for (int k = 0; k < 3; ++k) f.rot[3 * k + c] = r[k];
    }
  }
  return f;
}

kernels::ContactShape<double> Collider::contact_shape(const Frame& f) const {
  kernels::ContactShape<double> c;
  c.sphere = shape == Shape::Sphere ? 1 : 0;
  for (int k = 0; k < 3; ++k) {
    c.center[k] = f.center[k];
    c.normal[k] = f.normal[k];
    c.omega[k] = f.omega[k];
    c.vlin[k] = f.vlin[k];
  }
  c.radius = radius;
  c.thickness = thickness;
  c.mu_static = mu_static;
  c.mu_kinetic = mu_kinetic;
  return c;
}

Collider::Contact Collider::query(const Frame& f, const double xp[3]) const {
  return query(f, xp, INFINITY);
}

Collider::Contact Collider::query(const Frame& f, const double xp[3], double cutoff) const {
  Contact ct{};
  if (shape != Shape::Mesh && cutoff < INFINITY) {
    // A vertex certainly at least `cutoff` away gets that lower bound without the exact query
    // (its square root, division and surface velocity): most vertices of a scene, every step.
    // "Certainly": the margins exceed the rounding of these expressions and of
    // kernels::contact_query's, so a vertex skipped here would also read >= cutoff there.
    const double r[3] = {xp[0] - f.center[0], xp[1] - f.center[1], xp[2] - f.center[2]};
    if (shape == Shape::Sphere) {
      const double reach = radius + thickness + cutoff;
      if (r[0] * r[0] + r[1] * r[1] + r[2] * r[2] > reach * reach * (1 + 1e-12)) {
        ct.distance = cutoff;
        return ct;
      }
    } else {
      const double d = r[0] * f.normal[0] + r[1] * f.normal[1] + r[2] * f.normal[2] - thickness;
      if (d > cutoff + 1e-12 * (std::abs(r[0]) + std::abs(r[1]) + std::abs(r[2]) + thickness + std::abs(cutoff))) {
        ct.distance = cutoff;
        return ct;
      }
    }
  }
  if (shape != Shape::Mesh) {  // sphere, plane: the shared kernel (loom/kernels/contact.hpp)
    ct.distance = kernels::contact_query(contact_shape(f), xp, ct.normal.data(), ct.velocity.data());
  } else {
    // The mesh query (into the body frame and back): one source with the CUDA backend.
    ct.distance = kernels::mesh_contact_query(body->view(), mesh_placement(*this, f), xp, cutoff, ct.normal.data(),
                                              ct.velocity.data());
  }
  return ct;
}

kernels::MeshPlacement mesh_placement(const Collider& c, const Collider::Frame& f) {
  kernels::MeshPlacement m;
  for (int k = 0; k < 3; ++k) {
    m.center[k] = f.center[k];
    m.pivot[k] = c.point[k];
    m.omega[k] = f.omega[k];
    m.vlin[k] = f.vlin[k];
  }
  for (int k = 0; k < 9; ++k) m.rot[k] = f.rot[k];
  m.thickness = c.thickness;
  return m;
}

int ColliderSet::resolve_contacts(State& s, double t, double h) const {
  if (colliders_.empty()) return 0;
  // Placements once per call, not per vertex. A scene has a handful of colliders: a stack
  // array covers them without allocating; more than that (rare) uses a vector.
  constexpr std::size_t kStackFrames = 16;
  const std::size_t nc = colliders_.size();
  if (nc > kStackFrames) {
    std::vector<Collider::Frame> many(nc);
    for (std::size_t c = 0; c < nc; ++c) many[c] = colliders_[c].frame_at(t);
    return resolve_with_frames(s, many.data(), h);
  }
  Collider::Frame frames[kStackFrames];
  for (std::size_t c = 0; c < nc; ++c) frames[c] = colliders_[c].frame_at(t);
  return resolve_with_frames(s, frames, h);
}

int ColliderSet::resolve_with_frames(State& s, const Collider::Frame* frames, double h) const {
  const Index n = s.size();
  const std::size_t nc = colliders_.size();
  int contacts = 0;
#pragma omp parallel for reduction(+ : contacts) schedule(static) if (n >= kParallelMinVertices)
  for (Index i = 0; i < n; ++i) {
    if (s.pinned[i]) continue;
    double* x = &s.x[3 * i];
    double* v = &s.v[3 * i];
    for (std::size_t c = 0; c < nc; ++c) {
      const Collider& col = colliders_[c];
      const Collider::Contact ct = col.query(frames[c], x, 0.0);  // exact where < 0: all this pass needs
      if (ct.distance >= 0) continue;
      ++contacts;
      // Projection, inelastic normal part, Coulomb friction: one source with the CUDA backend.
      kernels::contact_respond(x, v, ct.distance, ct.normal.data(), ct.velocity.data(), col.mu_static, col.mu_kinetic, h);
    }
  }
  return contacts;
}

namespace {


Vec3 unit(const Params& p, const std::string& key, Vec3 v) {
  const double len = norm(v);
  if (!(len > 1e-12)) p.child(key).fail("must be a non-zero vector.");
  return scale(v, 1.0 / len);
}

}  // namespace

ColliderSet ColliderSet::parse(const Params& list, const std::string& base_dir) {
  ColliderSet set;
  if (!list.valid()) return set;
  if (!list.is_sequence()) list.fail("must be a list of colliders, e.g. colliders: [{type: plane, point: [0,0,0], normal: [0,1,0]}].");
  for (std::size_t k = 0; k < list.size(); ++k) {
    const Params p = with_section_spec(list.at(k), "colliders");  // its keys: section_specs.cpp
    if (!p.is_map()) p.fail("a collider is a mapping with 'type' (sphere, plane or mesh).");
    Collider c;
    const std::string type = p.get_choice("type", "", {"sphere", "plane", "mesh"});
    if (type.empty()) p.fail("missing 'type': sphere, plane or mesh.");
    c.name = p.get("name", type + " " + std::to_string(k));
    if (type == "sphere") {
      c.shape = Collider::Shape::Sphere;
      c.point = read_vec3(p, "center", {0, 0, 0}, true);
      Params r = p.child("radius");
      if (!r.valid()) p.fail("a sphere needs 'radius' (m, > 0).");
      c.radius = r.as_double();
      if (!std::isfinite(c.radius) || c.radius <= 0) r.fail("radius must be a finite number > 0 (got " + std::to_string(c.radius) + ").");
    } else if (type == "mesh") {
      c.shape = Collider::Shape::Mesh;
      Params obj = p.child("obj");
      if (!obj.valid()) p.fail("a mesh collider needs 'obj': the path of a triangle mesh (OBJ, relative to the scene file).");
      std::string path = obj.as_string();
      if (!path.empty() && !base_dir.empty() && std::filesystem::path(path).is_relative())
        path = (std::filesystem::path(base_dir) / path).lexically_normal().string();
      const double scale = p.get_positive("scale", 1.0);
      const Vec3 offset = read_vec3(p, "offset", {0, 0, 0});
      try {
        c.body = MeshBody::load(path, scale, offset);
      } catch (const InputError& e) {
        obj.fail(std::string("mesh collider: ") + e.what());
      }
      c.point = read_vec3(p, "pivot", c.body->box_center());
    } else {
      c.shape = Collider::Shape::Plane;
      c.point = read_vec3(p, "point", {0, 0, 0});
      c.normal = unit(p, "normal", read_vec3(p, "normal", {0, 1, 0}));
    }
    c.thickness = p.get_nonnegative("thickness", 0.0);
    Params fr = p.child("friction");
    if (fr.is_scalar()) {
      c.mu_static = c.mu_kinetic = p.get_nonnegative("friction", 0.0);
    } else if (fr.is_map()) {
      c.mu_static = fr.get_nonnegative("static", 0.0);
      c.mu_kinetic = fr.get_nonnegative("kinetic", c.mu_static);
      fr.check_unused();
      if (c.mu_kinetic > c.mu_static)
        fr.fail("kinetic friction (" + std::to_string(c.mu_kinetic) + ") must not exceed static friction (" +
                std::to_string(c.mu_static) + ").");
    } else if (fr.valid()) {
      fr.fail("friction is a number or {static: mu_s, kinetic: mu_k}.");
    }
    Params m = p.child("motion");
    if (m.valid()) c.motion = parse_rigid_motion(m);
    p.check_unused();
    set.add(c);
  }
  return set;
}

}  // namespace loom
