// Mesh colliders: signed distance against exact answers (a cube's box distance, the analytic
// sphere behind an icosphere within its faceting depth), open meshes, rigid motion, contact
// through resolve_contacts, and bad input (file, line, fix).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "loom/collider.hpp"
#include "loom/mesh_collider.hpp"

namespace fs = std::filesystem;

namespace {

// Axis-aligned cube [-h, h]^3, 8 vertices and 12 triangles wound outward (or inward).
std::shared_ptr<loom::MeshBody> cube(double h, bool inward = false) {
  std::vector<double> x;
  for (int i = 0; i < 8; ++i) x.insert(x.end(), {(i & 1) ? h : -h, (i & 2) ? h : -h, (i & 4) ? h : -h});
  // quads (counter-clockwise seen from outside)
  const int q[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  std::vector<loom::Index> t;
  for (const auto& f : q) {
    if (inward) t.insert(t.end(), {f[0], f[2], f[1], f[0], f[3], f[2]});
    else t.insert(t.end(), {f[0], f[1], f[2], f[0], f[2], f[3]});
  }
  return loom::MeshBody::build(x, t, "cube");
}

// Exact signed distance to the box [-h, h]^3.
double box_sdf(const double* p, double h) {
  double out2 = 0, in = -1e300;
  for (int k = 0; k < 3; ++k) {
    const double d = std::abs(p[k]) - h;
    out2 += d > 0 ? d * d : 0;
    in = std::max(in, d);
  }
  return in > 0 ? std::sqrt(out2) : in;
}

loom::ColliderSet parse(const std::string& yaml, const std::string& base = LOOM_SOURCE_DIR "/scenes") {
  return loom::ColliderSet::parse(loom::Params::from_string(yaml, "scene.yaml").child("colliders"), base);
}

std::string error_of(const std::string& yaml, const std::string& base) {
  try {
    parse(yaml, base);
  } catch (const loom::InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(MeshCollider, CubeSignedDistanceIsTheExactBoxDistanceInsideAndOut) {
  for (const bool inward : {false, true}) {
    const auto b = cube(0.5, inward);
    EXPECT_TRUE(b->closed());
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> U(-1.2, 1.2);
    for (int i = 0; i < 4000; ++i) {
      const double p[3] = {U(rng), U(rng), U(rng)};
      double n[3], q[3];
      const double d = b->signed_distance(p, n, q);
      ASSERT_NEAR(d, box_sdf(p, 0.5), 1e-12) << p[0] << " " << p[1] << " " << p[2] << " inward " << inward;
      // The normal is the exact distance gradient where the distance is not zero: a unit
      // vector with p - d n on the surface.
      const double pn[3] = {p[0] - d * n[0], p[1] - d * n[1], p[2] - d * n[2]};
      ASSERT_NEAR(box_sdf(pn, 0.5), 0.0, 1e-12);
      ASSERT_NEAR(n[0] * n[0] + n[1] * n[1] + n[2] * n[2], 1.0, 1e-12);
    }
    // On the corner, edge and face exactly: zero distance, pseudo-normal outward.
    for (const auto& p : {std::array<double, 3>{0.5, 0.5, 0.5}, {0.5, 0.5, 0.1}, {0.5, 0.2, -0.3}}) {
      double n[3], q[3];
      EXPECT_NEAR(b->signed_distance(p.data(), n, q), 0.0, 1e-15);
      EXPECT_GT(n[0] * p[0] + n[1] * p[1] + n[2] * p[2], 0.0);
    }
  }
}

TEST(MeshCollider, IcosphereAgainstTheAnalyticSphereWithinItsFacetingDepth) {
  const double R = 0.3;
  const auto b = loom::MeshBody::load(LOOM_SOURCE_DIR "/scenes/meshes/icosphere3.obj", R, {1, 2, 3});
  EXPECT_TRUE(b->closed());
  EXPECT_EQ(b->num_triangles(), 1280);
  // Depth of the faces below the sphere, from the mesh itself.
  double depth = 0;
  const auto& x = b->positions();
  const auto& t = b->triangles();
  for (loom::Index f = 0; f < b->num_triangles(); ++f) {
    const double* a = &x[3 * t[3 * f]];
    const double* c1 = &x[3 * t[3 * f + 1]];
    const double* c2 = &x[3 * t[3 * f + 2]];
    double u[3], w[3];
    for (int k = 0; k < 3; ++k) {
      u[k] = c1[k] - a[k];
      w[k] = c2[k] - a[k];
    }
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    const double ln = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    const double plane = (n[0] * (a[0] - 1) + n[1] * (a[1] - 2) + n[2] * (a[2] - 3)) / ln;
    depth = std::max(depth, R - plane);
  }
  EXPECT_GT(depth, 0.0);
  EXPECT_LT(depth, 0.005 * R);  // 0.0045 R for 3 subdivisions (scripts/make_icosphere.py)
  std::mt19937 rng(9);
  std::normal_distribution<double> N(0, 1);
  std::uniform_real_distribution<double> U(0, 2 * R);
  for (int i = 0; i < 3000; ++i) {
    double dir[3] = {N(rng), N(rng), N(rng)};
    const double l = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
    const double r = U(rng);
    const double p[3] = {1 + r * dir[0] / l, 2 + r * dir[1] / l, 3 + r * dir[2] / l};
    double n[3], q[3];
    const double d = b->signed_distance(p, n, q);
    const double exact = r - R;
    // The mesh lies between the sphere and the sphere shrunk by `depth`.
    ASSERT_GE(d, exact - 1e-12) << r;
    ASSERT_LE(d, exact + depth + 1e-12) << r;
    // The normal points outward: nearly radial well outside, and within a face's angular size
    // (~5 degrees here) inside, down to half the radius (near the centre any face is nearest).
    const double radial = (n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2]) / l;
    if (exact > 0.2 * R) {
      ASSERT_GT(radial, 0.99) << r;
    }
    if (r > 0.5 * R) {
      ASSERT_GT(radial, 0.95) << r;
    }
  }
}

TEST(MeshCollider, OpenMeshFrontIsOutside) {
  // A 2 x 2 table top at y = 0.7, facing +y, from the two triangles of a square.
  const auto b = loom::MeshBody::build({-1, 0.7, -1, 1, 0.7, -1, 1, 0.7, 1, -1, 0.7, 1}, {0, 2, 1, 0, 3, 2}, "top");
  EXPECT_FALSE(b->closed());
  double n[3], q[3];
  const double above[3] = {0.2, 0.9, 0.3}, below[3] = {0.2, 0.65, 0.3}, beside[3] = {1.5, 0.8, 0};
  EXPECT_NEAR(b->signed_distance(above, n, q), 0.2, 1e-15);
  EXPECT_NEAR(n[1], 1.0, 1e-15);
  EXPECT_NEAR(b->signed_distance(below, n, q), -0.05, 1e-15);
  EXPECT_NEAR(n[1], 1.0, 1e-15);  // pushed back out to the front
  EXPECT_NEAR(b->signed_distance(beside, n, q), std::hypot(0.5, 0.1), 1e-15);
}

TEST(MeshCollider, CutoffQueryIsExactBelowTheCutoffAndALowerBoundAbove) {
  // The cutoff query against the full one, on closed meshes wound both ways, the icosphere and
  // an open table top, with points inside, near and far outside the bounding boxes.
  const auto ico = loom::MeshBody::load(LOOM_SOURCE_DIR "/scenes/meshes/icosphere3.obj", 0.3, {0, 0, 0});
  const auto top = loom::MeshBody::build({-1, 0.7, -1, 1, 0.7, -1, 1, 0.7, 1, -1, 0.7, 1}, {0, 2, 1, 0, 3, 2}, "top");
  const std::shared_ptr<loom::MeshBody> bodies[] = {cube(0.5), cube(0.5, true), ico, top};
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> U(-2.5, 2.5);
  int below = 0, above = 0;
  for (const auto& b : bodies)
    for (const double cutoff : {0.0, 0.004, 0.05, 0.4})
      for (int i = 0; i < 2000; ++i) {
        const double p[3] = {U(rng), U(rng), U(rng)};
        double n[3], q[3], nc[3], qc[3];
        const double d = b->signed_distance(p, n, q);
        const double dc = b->signed_distance(p, nc, qc, cutoff);
        if (d < cutoff) {
          ++below;
          ASSERT_EQ(dc, d) << b->source() << " cutoff " << cutoff;
          for (int k = 0; k < 3; ++k) {
            ASSERT_EQ(nc[k], n[k]);
            ASSERT_EQ(qc[k], q[k]);
          }
        } else {
          ++above;
          ASSERT_GE(dc, cutoff) << b->source();
          ASSERT_LE(dc, d + 1e-12) << b->source();  // the box distance of a cube is its distance, up to rounding
        }
      }
  EXPECT_GT(below, 1000);  // both branches are exercised
  EXPECT_GT(above, 1000);
}

TEST(MeshCollider, RigidMotionMovesTheBodyAndGivesTheSurfaceVelocity) {
  // A cube of half-size 0.5 about (1, 0, 0), rotating about +y at 2 rad/s and translating.
  std::ofstream(fs::temp_directory_path() / "loom_cube.obj") << [] {
    std::string s;
    const auto b = cube(0.5);
    for (loom::Index v = 0; v < b->num_vertices(); ++v)
      s += "v " + std::to_string(b->positions()[3 * v] + 1) + " " + std::to_string(b->positions()[3 * v + 1]) + " " +
           std::to_string(b->positions()[3 * v + 2]) + "\n";
    for (loom::Index f = 0; f < b->num_triangles(); ++f)
      s += "f " + std::to_string(b->triangles()[3 * f] + 1) + " " + std::to_string(b->triangles()[3 * f + 1] + 1) + " " +
           std::to_string(b->triangles()[3 * f + 2] + 1) + "\n";
    return s;
  }();
  const std::string base = fs::temp_directory_path().string();
  const auto rot = parse("colliders: [{type: mesh, obj: loom_cube.obj, thickness: 0.01, "
                         "motion: {type: rotate, axis: [0, 1, 0], angular_velocity: 2.0}}]",
                         base);
  const loom::Collider& c = rot.colliders()[0];
  EXPECT_NEAR(c.point[0], 1.0, 1e-12);  // default pivot: the bounding-box centre
  const double t = 0.3, a = 2.0 * t;
  // A world point x: its distance is the box distance of R(-a) (x - centre).
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> U(-1, 1);
  for (int i = 0; i < 500; ++i) {
    const double x[3] = {1 + U(rng), U(rng), U(rng)};
    const double rx = x[0] - 1, rz = x[2];
    // rotation about +y by angle a: (x, z) -> (x cos a + z sin a, -x sin a + z cos a); inverse uses -a
    const double body[3] = {rx * std::cos(a) - rz * std::sin(a), x[1], rx * std::sin(a) + rz * std::cos(a)};
    const loom::Collider::Contact ct = c.query(x, t);
    ASSERT_NEAR(ct.distance, box_sdf(body, 0.5) - 0.01, 1e-12);
    // Surface velocity omega x (s - centre) at the contact point s = x - (d + thickness) n.
    const double d = ct.distance + 0.01;
    const double s[3] = {x[0] - d * ct.normal[0] - 1, x[1] - d * ct.normal[1], x[2] - d * ct.normal[2]};
    ASSERT_NEAR(ct.velocity[0], 2.0 * s[2], 1e-12);  // (0, w, 0) x s = (w s_z, 0, -w s_x)
    ASSERT_NEAR(ct.velocity[1], 0.0, 1e-12);
    ASSERT_NEAR(ct.velocity[2], -2.0 * s[0], 1e-12);
  }
  const auto tr = parse("colliders: [{type: mesh, obj: loom_cube.obj, motion: {type: translate, velocity: [0, 1, 0]}}]", base);
  const double x[3] = {1.2, 1.0, 0.1};  // at t = 0.8 the cube's top is at y = 1.3
  const auto ct = tr.colliders()[0].query(x, 0.8);
  EXPECT_NEAR(ct.distance, -0.3, 1e-12);
  EXPECT_NEAR(ct.velocity[1], 1.0, 1e-15);
}

TEST(MeshCollider, ParticleDroppedOnTheMeshSphereStaysOut) {
  // resolve_contacts (explicit integrators): a particle falling on the icosphere's top vertex.
  const auto set = parse("colliders: [{type: mesh, obj: meshes/icosphere3.obj, scale: 0.3, offset: [0, -0.3, 0], "
                         "thickness: 0.005, friction: 0.5}]");
  loom::State s;
  s.resize(1);
  s.mass[0] = 1;
  s.update_inverse_masses();
  s.x = {0.013, 0.2, -0.021};
  const double h = 1e-3;
  for (int k = 0; k < 1500; ++k) {
    s.v[1] -= h * 9.81;
    for (int c = 0; c < 3; ++c) s.x[c] += h * s.v[c];
    s.time += h;
    set.resolve_contacts(s, s.time, h);
    ASSERT_GE(set.colliders()[0].query(s.x.data(), s.time).distance, -1e-12);
  }
  // Resting near the top (friction holds it on the nearly flat top).
  EXPECT_NEAR(std::hypot(s.x[0], s.x[1] + 0.3, s.x[2]), 0.3 + 0.005, 0.3 * 0.005);
  EXPECT_LT(std::abs(s.v[1]), 1e-9);
}

TEST(MeshCollider, BadInputNamesFileLineAndFix) {
  const fs::path d = fs::temp_directory_path() / "loom_mesh_bad";
  fs::remove_all(d);
  fs::create_directories(d);
  const std::string base = d.string();
  auto yaml = [](const std::string& obj, const std::string& extra = "") {
    return "colliders:\n  - {type: mesh, obj: " + obj + extra + "}\n";
  };
  // Missing file: the scene line and the path.
  std::string e = error_of(yaml("nothere.obj"), base);
  EXPECT_NE(e.find("scene.yaml:2"), std::string::npos) << e;
  EXPECT_NE(e.find("nothere.obj: cannot open"), std::string::npos) << e;
  // Empty file.
  std::ofstream(d / "empty.obj") << "# nothing\n";
  e = error_of(yaml("empty.obj"), base);
  EXPECT_NE(e.find("empty.obj: no vertices"), std::string::npos) << e;
  // NaN coordinate: the OBJ line.
  std::ofstream(d / "nan.obj") << "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n";
  e = error_of(yaml("nan.obj"), base);
  EXPECT_NE(e.find("nan.obj:3"), std::string::npos) << e;
  // Non-manifold: three faces on the edge 1-2 (the third one's line is named).
  std::ofstream(d / "fan.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\n# three fins\nf 1 2 3\nf 2 1 4\nf 1 2 5\n";
  e = error_of(yaml("fan.obj"), base);
  EXPECT_NE(e.find("fan.obj:9: non-manifold"), std::string::npos) << e;
  EXPECT_NE(e.find("Fix:"), std::string::npos) << e;
  // Two faces traversing an edge the same way.
  std::ofstream(d / "flip.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nf 1 2 3\nf 1 2 4\n";
  e = error_of(yaml("flip.obj"), base);
  EXPECT_NE(e.find("flip.obj:6: inconsistent face orientation"), std::string::npos) << e;
  // Keyframes out of time order: the keyframe's line in the scene.
  std::ofstream(d / "ok.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  e = error_of("colliders:\n  - type: mesh\n    obj: ok.obj\n    motion:\n      type: keyframes\n      keys:\n"
               "        - {t: 0.0, translate: [0, 0, 0]}\n        - {t: 0.5, translate: [0, 1, 0]}\n"
               "        - {t: 0.2, translate: [0, 2, 0]}\n",
               base);
  EXPECT_NE(e.find("scene.yaml:9"), std::string::npos) << e;
  EXPECT_NE(e.find("keyframe times must increase"), std::string::npos) << e;
  // scale must be positive; obj is required.
  EXPECT_NE(error_of(yaml("ok.obj", ", scale: 0"), base).find("scale"), std::string::npos);
  EXPECT_NE(error_of("colliders: [{type: mesh}]", base).find("needs 'obj'"), std::string::npos);
  // The good one parses: an open single triangle.
  EXPECT_FALSE(parse(yaml("ok.obj"), base).colliders()[0].body->closed());
}
