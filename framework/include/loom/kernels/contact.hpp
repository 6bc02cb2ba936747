// Analytic collider contact (sphere, plane) per vertex: the query (signed distance to the
// offset surface, outward normal, surface velocity) and the response (projection onto the
// surface, inelastic normal velocity, Coulomb friction). Header-only and LOOM_HD: the CPU
// ColliderSet (framework/src/collider.cpp) and the CUDA backend run this one source, so the
// contact rules are the same on both backends. Templated on the scalar.
//
// Response (after an explicit step of size h; docs/CONTACT.md): a vertex with distance d < 0
// moves by -d n onto the offset surface. Its velocity relative to the surface, vrel = v - vs,
// keeps its normal part when separating (vn >= 0); otherwise the normal part is removed
// (dvn = -vn) and the tangential part vt obeys Coulomb: it sticks (vt = 0) when
// |vt| <= mu_s dvn, else loses mu_k dvn of its length (never reversing). The tangential
// velocity change is also applied to the position (h (vt_new - vt_old)), as if the step had
// moved with the corrected velocity.
#pragma once

#include <cmath>

#include "loom/common.hpp"

namespace loom::kernels {

/// A sphere or plane placed at one time (Collider::frame_at), in plain data.
template <class T>
struct ContactShape {
  int sphere = 0;      ///< 1 sphere, 0 plane
  T center[3] = {};    ///< sphere centre or a point on the plane, at the time
  T normal[3] = {};    ///< plane normal at the time (unit)
  T omega[3] = {};     ///< angular velocity
  T vlin[3] = {};      ///< linear velocity of the centre
  T radius = 0, thickness = 0, mu_static = 0, mu_kinetic = 0;
};

template <class T>
LOOM_HD inline void contact_cross(const T a[3], const T b[3], T c[3]) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}

/// Signed distance to the offset surface (< 0: inside), outward unit normal n and the
/// surface velocity vs at point x.
template <class T>
LOOM_HD inline T contact_query(const ContactShape<T>& c, const T x[3], T n[3], T vs[3]) {
  T arm[3], d;
  if (c.sphere) {
    const T r[3] = {x[0] - c.center[0], x[1] - c.center[1], x[2] - c.center[2]};
    using std::sqrt;
    const T len = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    if (static_cast<double>(len) > 1e-300) {  // (compared in double: a float length is > 0 then)
      const T il = T(1) / len;
      for (int k = 0; k < 3; ++k) n[k] = r[k] * il;
    } else {
      n[0] = T(0), n[1] = T(1), n[2] = T(0);
    }
    d = len - c.radius - c.thickness;
    for (int k = 0; k < 3; ++k) arm[k] = n[k] * c.radius;
  } else {
    for (int k = 0; k < 3; ++k) n[k] = c.normal[k];
    d = (x[0] - c.center[0]) * n[0] + (x[1] - c.center[1]) * n[1] + (x[2] - c.center[2]) * n[2] - c.thickness;
    const T s = d + c.thickness;
    for (int k = 0; k < 3; ++k) arm[k] = (x[k] - n[k] * s) - c.center[k];  // surface point - centre
  }
  T w[3];
  contact_cross(c.omega, arm, w);
  for (int k = 0; k < 3; ++k) vs[k] = c.vlin[k] + w[k];
  return d;
}

/// The response of one vertex (x, v updated in place) to a contact found by contact_query
/// (distance d < 0, normal n, surface velocity vs).
template <class T>
LOOM_HD inline void contact_respond(T x[3], T v[3], T d, const T n[3], const T vs[3], T mu_static, T mu_kinetic, T h) {
  for (int k = 0; k < 3; ++k) x[k] -= d * n[k];  // onto the offset surface
  const T vrel[3] = {v[0] - vs[0], v[1] - vs[1], v[2] - vs[2]};
  const T vn = vrel[0] * n[0] + vrel[1] * n[1] + vrel[2] * n[2];
  if (vn >= T(0)) return;  // already separating
  const T vt_old[3] = {vrel[0] - n[0] * vn, vrel[1] - n[1] * vn, vrel[2] - n[2] * vn};
  const T dvn = -vn;  // normal velocity removed (>= 0)
  using std::sqrt;
  const T vt_len = sqrt(vt_old[0] * vt_old[0] + vt_old[1] * vt_old[1] + vt_old[2] * vt_old[2]);
  T scale = T(1);
  if (vt_len <= mu_static * dvn) {
    scale = T(0);  // static friction: stick
  } else if (mu_kinetic > T(0)) {
    const T s = T(1) - mu_kinetic * dvn / vt_len;
    scale = s > T(0) ? s : T(0);
  }
  for (int k = 0; k < 3; ++k) {
    const T vt = vt_old[k] * scale;
    v[k] = vs[k] + vt;
    x[k] += h * (vt - vt_old[k]);  // move as the corrected tangential velocity would have
  }
}

}  // namespace loom::kernels
