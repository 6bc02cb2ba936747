#include "loom/collider_geometry.hpp"

#include <cmath>

#include "loom/mesh_collider.hpp"

namespace loom {

namespace {

void push(std::vector<float>& out, const double* p) {
  out.push_back(static_cast<float>(p[0]));
  out.push_back(static_cast<float>(p[1]));
  out.push_back(static_cast<float>(p[2]));
}

// Rotate v by the frame's body -> world rotation.
void rotate(const double* R, const double* v, double* out) {
  for (int k = 0; k < 3; ++k) out[k] = R[3 * k] * v[0] + R[3 * k + 1] * v[1] + R[3 * k + 2] * v[2];
}

}  // namespace

void collider_triangles(const ColliderSet& colliders, double t, const double focus[3], double plane_size,
                        std::vector<float>& pos, std::vector<float>& nrm) {
  for (const Collider& c : colliders.colliders()) {
    const Collider::Frame f = c.frame_at(t);
    if (c.shape == Collider::Shape::Sphere) {
      // Latitude-longitude tessellation, 48 x 24.
      const int nu = 48, nv = 24;
      auto vertex = [&](int i, int j, double* p, double* n) {
        const double th = M_PI * j / nv, ph = 2 * M_PI * i / nu;
        n[0] = std::sin(th) * std::cos(ph);
        n[1] = std::cos(th);
        n[2] = std::sin(th) * std::sin(ph);
        for (int k = 0; k < 3; ++k) p[k] = f.center[k] + c.radius * n[k];
      };
      for (int j = 0; j < nv; ++j)
        for (int i = 0; i < nu; ++i) {
          double p[4][3], n[4][3];
          vertex(i, j, p[0], n[0]);
          vertex(i + 1, j, p[1], n[1]);
          vertex(i + 1, j + 1, p[2], n[2]);
          vertex(i, j + 1, p[3], n[3]);
          for (int q : {0, 1, 2, 0, 2, 3}) {
            push(pos, p[q]);
            push(nrm, n[q]);
          }
        }
    } else if (c.shape == Collider::Shape::Plane) {
      const double* n = f.normal.data();
      // Two unit vectors spanning the plane.
      double a[3] = {1, 0, 0};
      if (std::abs(n[0]) > 0.9) a[0] = 0, a[1] = 1;
      double u[3] = {n[1] * a[2] - n[2] * a[1], n[2] * a[0] - n[0] * a[2], n[0] * a[1] - n[1] * a[0]};
      const double lu = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
      for (double& x : u) x /= lu;
      const double w[3] = {n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2], n[0] * u[1] - n[1] * u[0]};
      const double d = (focus[0] - f.center[0]) * n[0] + (focus[1] - f.center[1]) * n[1] + (focus[2] - f.center[2]) * n[2];
      const double o[3] = {focus[0] - d * n[0], focus[1] - d * n[1], focus[2] - d * n[2]};
      const double s = 0.5 * plane_size;
      double p[4][3];
      const double cu[4] = {-s, s, s, -s}, cw[4] = {-s, -s, s, s};
      for (int q = 0; q < 4; ++q)
        for (int k = 0; k < 3; ++k) p[q][k] = o[k] + cu[q] * u[k] + cw[q] * w[k];
      for (int q : {0, 1, 2, 0, 2, 3}) {
        push(pos, p[q]);
        push(nrm, n);
      }
    } else if (c.body) {
      // Body frame -> world: R (y - c0) + c(t); flat-shaded faces.
      const auto& x = c.body->positions();
      const auto& tri = c.body->triangles();
      for (Index t3 = 0; t3 < c.body->num_triangles(); ++t3) {
        double p[3][3];
        for (int v = 0; v < 3; ++v) {
          const double* y = &x[3 * tri[3 * t3 + v]];
          const double r[3] = {y[0] - c.point[0], y[1] - c.point[1], y[2] - c.point[2]};
          rotate(f.rot, r, p[v]);
          for (int k = 0; k < 3; ++k) p[v][k] += f.center[k];
        }
        const double e1[3] = {p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
        const double e2[3] = {p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
        double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
        const double ln = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (ln > 0)
          for (double& v : n) v /= ln;
        for (int v = 0; v < 3; ++v) {
          push(pos, p[v]);
          push(nrm, n);
        }
      }
    }
  }
}

}  // namespace loom
