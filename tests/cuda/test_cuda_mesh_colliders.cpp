// Mesh colliders on the CUDA backend (issue 17), through the Thrust-OpenMP stand-in (and on a
// GPU as test_cuda_gpu): the device runs the CPU's own mesh query (loom/kernels/mesh_query.hpp:
// the BVH traversal in the body frame, pseudo-normal sign, thickness, surface velocity) on
// device copies of the body, with the placement computed on the host per step.
// - The query itself: device against Collider::query on points around closed and open meshes,
//   fixed and moving, at the cutoffs the integrators use.
// - A small cloth falling onto a static mesh (the shipped icosphere; an open tilted quad), a
//   rotating one (the shipped draped_mesh_sphere_gnatv_bw ball, with friction) and a keyframed
//   one (rotation and translation, smooth keys): every integrator of the backend (HO, RK4,
//   symplectic Euler, Baraff-Witkin) against the CPU integrator, positions and velocities after
//   N steps within 1e-10 relative in double; the float path within its measured bound.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "baraff_witkin.hpp"
#include "cuda_integrators.hpp"
#include "cuda_test_compare.hpp"
#include "cuda_test_pcg.hpp"
#include "cuda_test_scenes.hpp"
#include "device_colliders.hpp"
#include "device_pcg.hpp"
#include "eigen_pcg.hpp"
#include "ho_integrator.hpp"
#include "loom/mesh.hpp"
#include "loom/mesh_collider.hpp"
#include "loom/scene.hpp"
#include "mass_spring.hpp"
#include "rk4_integrator.hpp"
#include "symplectic_euler.hpp"

using namespace loom;
namespace lc = loom::cuda;

namespace {

using loom_cuda_test::rel_diff;

const std::string kScenes = std::string(LOOM_SOURCE_DIR) + "/scenes";

ColliderSet parse_colliders(const std::string& yaml) {
  return ColliderSet::parse(Params::from_string(yaml, "<test>").child("colliders"), kScenes);
}

/// The shipped mesh-ball scene's collider: icosphere3 (1280 faces) of radius 0.3 centred at
/// (0.5, -0.35, -0.5), thickness 4 mm, friction 0.5 / 0.4, spinning about y at 2 rad/s.
ColliderSet shipped_mesh_ball() {
  const Params root = Params::from_file(kScenes + "/draped_mesh_sphere_gnatv_bw.yaml");
  return ColliderSet::parse(root.child("colliders"), kScenes);
}

/// The same ball, fixed.
ColliderSet static_mesh_ball() {
  ColliderSet s = shipped_mesh_ball();
  ColliderSet out;
  Collider c = s.colliders()[0];
  c.motion = RigidMotion{};
  out.add(c);
  return out;
}

/// An open mesh (a 1.2 m quad of two triangles, front facing up), tilted about x, under the
/// cloth; its back side counts as inside.
ColliderSet open_quad() {
  const double a = 0.15, c = std::cos(a), s = std::sin(a);
  std::vector<double> x;
  for (double pz : {0.1, -1.1})
    for (double px : {-0.1, 1.1}) {
      const double z = pz + 0.5;  // tilt about the line z = -0.5, y = -0.02
      x.insert(x.end(), {px, -0.02 + s * z, -0.5 + c * z});
    }
  // Counter-clockwise seen from above (+y): the front is up.
  std::vector<Index> tri = {0, 1, 2, 1, 3, 2};
  Collider col;
  col.shape = Collider::Shape::Mesh;
  col.name = "quad";
  col.body = MeshBody::build(x, tri, "<quad>");
  col.point = col.body->box_center();
  col.thickness = 0.002;
  col.mu_static = 0.3;
  col.mu_kinetic = 0.2;
  ColliderSet set;
  set.add(col);
  return set;
}

/// icosphere1 (80 faces: coarse, so vertex and edge features are often the nearest) of radius
/// 0.25, keyframed: turning by 0.6 rad about a tilted axis while moving, smooth keys, and held
/// after the last key.
ColliderSet keyframed_mesh() {
  return parse_colliders(R"(colliders:
  - {type: mesh, name: rock, obj: meshes/icosphere1.obj, scale: 0.25, offset: [0.5, -0.3, -0.5], thickness: 0.003,
     friction: {static: 0.3, kinetic: 0.2},
     motion: {type: keyframes, axis: [0.3, 1, 0.2], interpolation: smooth,
              keys: [{t: 0, angle: 0}, {t: 0.02, angle: 0.6, translate: [0.01, 0.02, -0.01]}]}}
)");
}

struct Case {
  const char* name;
  ColliderSet (*colliders)();
  double top;  // height of the collider's offset surface under the cloth's centre at t = 0
  /// Baraff-Witkin steps compared. Until 2026-11-30 the contact rule was discontinuous at
  /// distance 0 (a vertex projected onto the surface by the previous step was in contact when
  /// its distance rounded to <= 0), so where the backends' states differ by rounding (~1e-13)
  /// such a tie could go either way and the runs parted by a whole contact: the keyframed case
  /// met one at step 15 on the stand-in and earlier on an H200 (x 4.2e-4, v 0.14 relative after
  /// 14 steps). The rule now counts a vertex within BaraffWitkin::kContactTolerance as on the
  /// surface; measured on the stand-in, every case agrees to 1.7e-13 over 60 steps.
  int bw_steps;
};
// Tops: the icosphere's pole vertex (radius 0.3 at y) + thickness; the quad at the centre line;
// icosphere1's top vertex (0.25) + thickness.
const Case kCases[] = {
    {"static_ball", static_mesh_ball, -0.35 + 0.3 + 0.004, 60},
    {"open_quad", open_quad, -0.02 + 0.002, 20},
    {"spinning_ball", shipped_mesh_ball, -0.35 + 0.3 + 0.004, 60},
    {"keyframed", keyframed_mesh, -0.3 + 0.25 + 0.003, 60},
};

enum class Cloth { Explicit, Implicit };

/// The falling cloth of cuda_test_scenes.hpp centred over (0.5, -0.5), its plane at y0, falling
/// at `vy`, drifting along x at `drift`, seed 7.
std::unique_ptr<Scene> make_scene(const ColliderSet& cols, Index nx, double y0, double vy, double drift) {
  return loom_cuda_test::falling_cloth(cols, nx, 0.5, y0, -0.5, drift, vy, 7);
}

struct Outcome {
  double err_x = 0, err_v = 0;
  int contacts = 0;  // vertex contacts the CPU saw, summed over the steps
};

/// Nothing of the device cloth left inside a collider (the CPU's own query).
void expect_outside(const ColliderSet& cols, const Scene& dev, double slack) {
  for (const Collider& c : cols.colliders()) {
    const Collider::Frame f = c.frame_at(dev.state.time);
    for (Index i = 1; i < dev.state.size(); ++i) {
      EXPECT_GE(c.query(f, &dev.state.x[3 * i]).distance, -slack) << c.name << " vertex " << i;
    }
  }
}

/// An explicit integrator ("ho", "rk4", "se") on both backends; the CPU's contacts are resolved
/// after each step as Simulation::step does.
Outcome run_explicit(const ColliderSet& cols, const std::string& which, double y0, int steps,
                 lc::Precision prec = lc::Precision::Double) {
  auto cpu = make_scene(cols, 10, y0, -0.5, 0.3);
  auto dev = make_scene(cols, 10, y0, -0.5, 0.3);
  std::unique_ptr<Integrator> ci, di;
  if (which == "ho") {
    ci = std::make_unique<HoIntegrator>(HoVariant::Velocity);
    di = lc::make_cuda_ho(lc::HoVariantD::Velocity, prec);
  } else if (which == "rk4") {
    ci = std::make_unique<Rk4Integrator>();
    di = lc::make_cuda_rk4(prec);
  } else {
    ci = std::make_unique<symplectic_euler::SymplecticEuler>(Params());
    di = lc::make_cuda_symplectic_euler(prec);
  }
  EXPECT_FALSE(ci->handles_contacts());
  EXPECT_TRUE(di->handles_contacts());
  const double h = 2e-4;
  ci->prepare(*cpu, h);
  di->prepare(*dev, h);
  Outcome r;
  for (int k = 0; k < steps; ++k) {
    ci->step(*cpu, h);
    r.contacts += cpu->colliders.resolve_contacts(cpu->state, cpu->state.time, h);
    di->step(*dev, h);
  }
  EXPECT_DOUBLE_EQ(dev->state.time, cpu->state.time);
  r.err_x = rel_diff(dev->state.x, cpu->state.x);
  r.err_v = rel_diff(dev->state.v, cpu->state.v);
  expect_outside(cols, *dev, prec == lc::Precision::Float ? 1e-6 : 1e-12);
  return r;
}

/// Baraff-Witkin on both backends with the friction rule `implicit` (implicit_friction: inside
/// the solve, or the correction after it), both solved by filtered_pcg at 1e-13.
Outcome run_bw(const ColliderSet& cols, double y0, int steps, bool implicit) {
  auto cpu = make_scene(cols, 12, y0, -0.3, 0.1);
  auto dev = make_scene(cols, 12, y0, -0.3, 0.1);
  loom_cuda_test::tight_pcg(*cpu, *dev);
  BaraffWitkinOptions o;
  o.kang_cho_damping = 0.01;
  o.implicit_friction = implicit;
  BaraffWitkin ci(o);
  lc::BwOptionsD d;
  d.kang_cho_damping = o.kang_cho_damping;
  d.implicit_friction = implicit;
  auto di = lc::make_cuda_baraff_witkin(d, lc::Precision::Double);
  const double h = 1e-3;
  ci.prepare(*cpu, h);
  di->prepare(*dev, h);
  Outcome r;
  for (int k = 0; k < steps; ++k) {
    ci.step(*cpu, h);
    di->step(*dev, h);
    r.contacts += ci.contact_count();
  }
  EXPECT_DOUBLE_EQ(dev->state.time, cpu->state.time);
  r.err_x = rel_diff(dev->state.x, cpu->state.x);
  r.err_v = rel_diff(dev->state.v, cpu->state.v);
  expect_outside(cols, *dev, 1e-12);
  return r;
}

/// The device query of every point in `pts` (3 per point) at time t with `cutoff`.
struct QueryKernel {
  lc::DeviceShape<double> shape;
  const double* p;
  double cutoff;
  double *d, *n, *vs;
  LOOM_HD void operator()(Index i) const {
    d[i] = lc::device_query(shape, p + 3LL * i, cutoff, n + 3LL * i, vs + 3LL * i);
  }
};

}  // namespace

// The device query against Collider::query: points around each case's collider (inside,
// near the surface, outside the bounding box, far), at the start and in the middle of the
// motion, with the cutoffs the integrators use (0: explicit contacts and projection; 1e-6:
// Baraff-Witkin's constraint pass; INFINITY: its exact start distance). Distances, normals
// and surface velocities agree to rounding (1e-12; bit-equal on the stand-in in practice).
TEST(CudaMeshColliders, DeviceQueryMatchesTheCpuQuery) {
  for (const Case& cs : kCases) {
    const ColliderSet cols = cs.colliders();
    const Collider& col = cols.colliders()[0];
    lc::DeviceMeshes meshes;
    meshes.prepare(cols);
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const Index np = 600;
    std::vector<double> pts(3 * np);
    for (Index i = 0; i < np; ++i) {
      // Shells around the box centre: within 0.5 of the surface, some far out.
      const double scale = i % 10 == 0 ? 3.0 : 0.5;
      for (int k = 0; k < 3; ++k) pts[3 * i + k] = col.body->box_center()[k] + scale * u(rng);
    }
    lc::DVec<double> dp, dd(np), dn(3 * np), dvs(3 * np);
    lc::upload(pts, dp);
    int inside = 0, checked = 0;
    for (double t : {0.0, 0.013}) {
      for (double cutoff : {0.0, 1e-6, static_cast<double>(INFINITY)}) {
        lc::DeviceShape<double> shape[1];
        lc::fill_device_shapes(cols, meshes, t, shape);
        ASSERT_EQ(shape[0].mesh, 1);
        lc::parallel_for(np, QueryKernel{shape[0], lc::raw(dp), cutoff, lc::raw(dd), lc::raw(dn), lc::raw(dvs)});
        const std::vector<double> d = loom_cuda_test::to_host(dd), n = loom_cuda_test::to_host(dn),
                                  vs = loom_cuda_test::to_host(dvs);
        const Collider::Frame f = col.frame_at(t);
        for (Index i = 0; i < np; ++i) {
          const Collider::Contact c = col.query(f, &pts[3 * i], cutoff);
          EXPECT_NEAR(d[i], c.distance, 1e-12) << cs.name << " point " << i << " cutoff " << cutoff;
          if (!(c.distance < cutoff)) continue;  // only a lower bound there: normal unspecified
          ++checked;
          inside += c.distance < 0;
          for (int k = 0; k < 3; ++k) {
            EXPECT_NEAR(n[3 * i + k], c.normal[k], 1e-12) << cs.name << " point " << i;
            EXPECT_NEAR(vs[3 * i + k], c.velocity[k], 1e-12) << cs.name << " point " << i;
          }
        }
      }
    }
    EXPECT_GT(inside, 100) << cs.name;  // the sign matters: many points are inside / behind
    EXPECT_GT(checked, 800) << cs.name;
  }
}

class CudaMeshColliders : public ::testing::TestWithParam<std::tuple<std::string, int>> {};

// A cloth starting 2 mm into the collider's offset surface, falling at 0.5 m/s with a
// sideways drift: contacts (with sticking and sliding friction) from the first step.
TEST_P(CudaMeshColliders, MatchesTheCpuBackend) {
  const std::string which = std::get<0>(GetParam());
  const Case& cs = kCases[std::get<1>(GetParam())];
  const ColliderSet cols = cs.colliders();
  const bool bw = which.rfind("bw", 0) == 0;
  const Outcome r = bw ? run_bw(cols, cs.top - 0.002, cs.bw_steps, which == "bw")
                       : run_explicit(cols, which, cs.top - 0.002, 150);
  EXPECT_LE(r.err_x, 1e-10) << cs.name;
  EXPECT_LE(r.err_v, 1e-10) << cs.name;
  // Vertex contacts over the run (measured: explicit 82-6500, Baraff-Witkin 17-79).
  EXPECT_GT(r.contacts, bw ? 12 : 50) << cs.name;
  std::printf("[ measured ] %s %s: x %.2e v %.2e relative, %d vertex contacts\n", which.c_str(), cs.name, r.err_x,
              r.err_v, r.contacts);
}

INSTANTIATE_TEST_SUITE_P(IntegratorsAndMeshes, CudaMeshColliders,
                         ::testing::Combine(::testing::Values("ho", "rk4", "se", "bw", "bw_friction_after_solve"),
                                            ::testing::Values(0, 1, 2, 3)),
                         [](const auto& info) {
                           return std::get<0>(info.param) + "_" + kCases[std::get<1>(info.param)].name;
                         });

// Float on the device against the double CPU run (the mesh query itself runs in double).
TEST(CudaMeshColliders, FloatTracksDouble) {
  for (const char* which : {"ho", "rk4", "se"}) {
    const ColliderSet cols = shipped_mesh_ball();
    const Outcome r = run_explicit(cols, which, kCases[2].top - 0.002, 100, lc::Precision::Float);
    std::printf("[ measured ] float %s spinning_ball: x %.2e v %.2e relative\n", which, r.err_x, r.err_v);
    EXPECT_LE(r.err_x, 1e-5) << which;
    EXPECT_LE(r.err_v, 1e-2) << which;
    EXPECT_GT(std::max(r.err_x, r.err_v), 1e-12) << which;  // it really ran in float
  }
}
