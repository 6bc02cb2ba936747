// Colliders on the device: sphere, plane and mesh colliders placed at one time, as the plain
// data the contact kernels take by value, and the one query they call per vertex.
// - Sphere and plane: the CPU's kernel (loom/kernels/contact.hpp) on ContactShape<T>.
// - Mesh: the body-frame arrays and flattened hierarchy of MeshBody, uploaded once in
//   prepare() (DeviceMeshes), and the placement (rotation and translation at the step's
//   time, computed on the host by Collider::frame_at, passed by value); the query is the
//   CPU's own (loom/kernels/mesh_query.hpp: the stack-based BVH traversal in the body frame),
//   run in double also in a float run (the point is converted, the answer rounded to T).
// No allocation per step: placements are filled into the kernel structs on the host.
#pragma once

#include <memory>
#include <vector>

#include "device.hpp"
#include "loom/collider.hpp"
#include "loom/kernels/contact.hpp"
#include "loom/kernels/mesh_query.hpp"
#include "loom/mesh_collider.hpp"

namespace loom::cuda {

constexpr int kMaxDeviceColliders = 8;

/// One collider placed at one time.
template <class T>
struct DeviceShape {
  kernels::ContactShape<T> s;  ///< sphere / plane; for a mesh only mu_static, mu_kinetic are used
  int mesh = 0;                ///< 1: a mesh collider (m, place)
  kernels::MeshView m;         ///< device arrays of the body
  kernels::MeshPlacement place;
};

/// Signed distance to the offset surface (< 0 inside), outward unit normal and surface
/// velocity at x, exact below `cutoff` (sphere and plane: always exact), as Collider::query.
template <class T>
LOOM_HD inline T device_query(const DeviceShape<T>& c, const T x[3], double cutoff, T n[3], T vs[3]) {
  if (!c.mesh) return kernels::contact_query(c.s, x, n, vs);
  const double xd[3] = {static_cast<double>(x[0]), static_cast<double>(x[1]), static_cast<double>(x[2])};
  double nd[3], vd[3];
  const double d = kernels::mesh_contact_query(c.m, c.place, xd, cutoff, nd, vd);
  for (int k = 0; k < 3; ++k) {
    n[k] = static_cast<T>(nd[k]);
    vs[k] = static_cast<T>(vd[k]);
  }
  return static_cast<T>(d);
}

/// The mesh colliders' bodies on the device (one slot per collider, empty for sphere/plane).
class DeviceMeshes {
 public:
  void prepare(const ColliderSet& set) {
    meshes_.clear();
    for (const Collider& c : set.colliders()) {
      meshes_.push_back(nullptr);
      if (c.shape != Collider::Shape::Mesh) continue;
      if (!c.body) throw InputError("backend cuda: mesh collider '" + c.name + "' has no body (no OBJ was loaded)");
      auto d = std::make_unique<Body>();
      const MeshBody& b = *c.body;
      upload(b.positions(), d->x);
      upload(b.triangles(), d->tri);
      upload(b.face_normals(), d->face_n);
      upload(b.vertex_normals(), d->vert_n);
      upload(b.edge_normals(), d->edge_n);
      upload(b.nodes(), d->nodes);
      upload(b.leaf_order(), d->order);
      d->closed = b.closed() ? 1 : 0;
      meshes_.back() = std::move(d);
    }
  }
  /// Device bytes of the bodies of a scene's mesh colliders.
  static std::size_t bytes(const ColliderSet& set) {
    std::size_t total = 0;
    for (const Collider& c : set.colliders()) {
      if (c.shape != Collider::Shape::Mesh || !c.body) continue;
      const MeshBody& b = *c.body;
      total += sizeof(double) * (b.positions().size() + b.face_normals().size() + b.vertex_normals().size() +
                                 b.edge_normals().size()) +
               sizeof(Index) * (b.triangles().size() + b.leaf_order().size()) + sizeof(kernels::MeshNode) * b.nodes().size();
    }
    return total;
  }
  kernels::MeshView view(std::size_t c) const {
    kernels::MeshView m;
    const Body& d = *meshes_[c];
    m.x = raw(d.x);
    m.tri = raw(d.tri);
    m.face_n = raw(d.face_n);
    m.vert_n = raw(d.vert_n);
    m.edge_n = raw(d.edge_n);
    m.nodes = raw(d.nodes);
    m.order = raw(d.order);
    m.closed = d.closed;
    return m;
  }

 private:
  struct Body {
    DVec<double> x, face_n, vert_n, edge_n;
    DVec<Index> tri, order;
    DVec<kernels::MeshNode> nodes;
    int closed = 0;
  };
  std::vector<std::unique_ptr<Body>> meshes_;
};

/// The colliders placed at time t, as kernel data (scene order); returns their number.
template <class T>
int fill_device_shapes(const ColliderSet& set, const DeviceMeshes& meshes, double t, DeviceShape<T>* out) {
  const int count = static_cast<int>(set.size());
  for (int c = 0; c < count; ++c) {
    const Collider& col = set.colliders()[c];
    const Collider::Frame f = col.frame_at(t);
    DeviceShape<T>& o = out[c];
    o = DeviceShape<T>{};
    if (col.shape == Collider::Shape::Mesh) {
      o.mesh = 1;
      o.m = meshes.view(static_cast<std::size_t>(c));
      o.place = mesh_placement(col, f);
      o.s.thickness = static_cast<T>(col.thickness);
      o.s.mu_static = static_cast<T>(col.mu_static);
      o.s.mu_kinetic = static_cast<T>(col.mu_kinetic);
      continue;
    }
    const kernels::ContactShape<double> s = col.contact_shape(f);
    o.s.sphere = s.sphere;
    for (int a = 0; a < 3; ++a) {
      o.s.center[a] = static_cast<T>(s.center[a]);
      o.s.normal[a] = static_cast<T>(s.normal[a]);
      o.s.omega[a] = static_cast<T>(s.omega[a]);
      o.s.vlin[a] = static_cast<T>(s.vlin[a]);
    }
    o.s.radius = static_cast<T>(s.radius);
    o.s.thickness = static_cast<T>(s.thickness);
    o.s.mu_static = static_cast<T>(s.mu_static);
    o.s.mu_kinetic = static_cast<T>(s.mu_kinetic);
  }
  return count;
}

}  // namespace loom::cuda
