// Colliders: contact projection, no energy gain, friction against the analytic answers.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "loom/collider.hpp"

namespace {

constexpr double kG = 9.81;

loom::ColliderSet parse(const std::string& yaml) {
  return loom::ColliderSet::parse(loom::Params::from_string(yaml, "colliders.yaml").child("colliders"));
}

std::string error_of(const std::string& yaml) {
  try {
    parse(yaml);
  } catch (const loom::InputError& e) {
    return e.what();
  }
  return "";
}

// One free particle of unit mass, stepped by symplectic Euler under gravity g_vec,
// with contacts resolved after every step (what the framework does for explicit integrators).
struct Particle {
  loom::State s;
  explicit Particle(loom::Vec3 x0, loom::Vec3 v0 = {0, 0, 0}) {
    s.resize(1);
    s.mass[0] = 1;
    s.update_inverse_masses();
    for (int k = 0; k < 3; ++k) { s.x[k] = x0[k]; s.v[k] = v0[k]; }
  }
  void step(const loom::ColliderSet& c, double h, loom::Vec3 g = {0, -kG, 0}) {
    for (int k = 0; k < 3; ++k) s.v[k] += h * g[k];
    for (int k = 0; k < 3; ++k) s.x[k] += h * s.v[k];
    s.time += h;
    c.resolve_contacts(s, s.time, h);
  }
};

}  // namespace

TEST(Colliders, ParticleDroppedOnPlaneComesToRestWithoutBounceOrPenetration) {
  const auto c = parse("colliders: [{type: plane, point: [0, 0, 0], normal: [0, 1, 0], thickness: 0.01}]");
  Particle p({0.3, 1.0, 0.2});
  const double h = 1e-3;
  const double e0 = kG * 1.0;  // potential + kinetic per unit mass
  double emax = 0;
  for (int n = 0; n < 2000; ++n) {
    p.step(c, h);
    EXPECT_GE(p.s.x[1], 0.01 - 1e-12) << "penetration at step " << n;
    const double e = kG * p.s.x[1] + 0.5 * (p.s.v[0] * p.s.v[0] + p.s.v[1] * p.s.v[1] + p.s.v[2] * p.s.v[2]);
    emax = std::max(emax, e);
  }
  EXPECT_LE(emax, e0 + kG * h * h);  // no energy gain beyond one step's rounding of the fall
  EXPECT_NEAR(p.s.x[1], 0.01, 1e-12);
  EXPECT_LT(std::abs(p.s.v[1]), 1e-12);  // at rest: the normal velocity is removed every step
  EXPECT_DOUBLE_EQ(p.s.x[0], 0.3);
}

TEST(Colliders, FrictionlessTiltedPlaneGivesGSinTheta) {
  const double theta = M_PI / 6;
  // plane through the origin with normal tilted by theta about z: downhill is +x
  const std::string yaml = "colliders: [{type: plane, normal: [" + std::to_string(std::sin(theta)) + ", " +
                           std::to_string(std::cos(theta)) + ", 0]}]";
  const auto c = parse(yaml);
  Particle p({0, 0, 0});
  const double h = 1e-4, T = 1.0;
  const loom::Vec3 n = c.colliders()[0].normal;
  for (int k = 0; k < static_cast<int>(T / h); ++k) p.step(c, h);
  const loom::Vec3 down{n[1], -n[0], 0};  // unit vector along the slope, downhill
  const double s = p.s.x[0] * down[0] + p.s.x[1] * down[1];
  const double a = 2 * s / (T * T);
  const double expect = kG * std::sin(theta);
  EXPECT_NEAR(a / expect, 1.0, 2e-3) << "a = " << a;
}

TEST(Colliders, KineticFrictionOnSlopeAndStaticFrictionHolds) {
  const double theta = M_PI / 6;
  const std::string plane = "{type: plane, normal: [" + std::to_string(std::sin(theta)) + ", " +
                            std::to_string(std::cos(theta)) + ", 0], friction: {static: ";
  const double h = 1e-4, T = 1.0;
  {
    const auto c = parse("colliders: [" + plane + "0.2, kinetic: 0.2}}]");
    Particle p({0, 0, 0});
    for (int k = 0; k < static_cast<int>(T / h); ++k) p.step(c, h);
    const double s = std::hypot(p.s.x[0], p.s.x[1]);
    const double expect = kG * (std::sin(theta) - 0.2 * std::cos(theta));
    EXPECT_NEAR((2 * s / (T * T)) / expect, 1.0, 5e-3);
  }
  {
    const auto c = parse("colliders: [" + plane + "0.7, kinetic: 0.6}}]");  // tan(30 deg) = 0.577 < 0.7
    Particle p({0, 0, 0});
    for (int k = 0; k < static_cast<int>(T / h); ++k) p.step(c, h);
    EXPECT_LT(std::hypot(p.s.x[0], p.s.x[1]), 1e-6);
  }
}

TEST(Colliders, RotatingSphereDragsARestingParticleInTheSurfaceDirection) {
  // sphere of radius 0.5 spinning about +z at 2 rad/s: its top moves along -x at 1 m/s
  const auto c = parse("colliders: [{type: sphere, center: [0, 0, 0], radius: 0.5, friction: 0.8,"
                       " motion: {type: rotate, axis: [0, 0, 1], angular_velocity: 2.0}}]");
  Particle p({0, 0.5, 0});
  const double h = 1e-4, T = 0.05;
  for (int k = 0; k < static_cast<int>(T / h); ++k) p.step(c, h);
  // kinetic regime: the surface slips under the particle, which gains mu g per second
  EXPECT_NEAR(p.s.v[0] / (-0.8 * kG * T), 1.0, 0.05);  // dragged along -x at ~ mu g t
  EXPECT_GT(p.s.v[0], -1.0 - 1e-9);                  // never faster than the surface
  EXPECT_LT(p.s.x[0], 0.0);
  EXPECT_NEAR(std::abs(p.s.v[2]), 0.0, 1e-12);
}

TEST(Colliders, ContactReleasesWhenLifted) {
  const auto c = parse("colliders: [{type: plane, friction: 1.0}]");
  Particle p({0, 0, 0}, {0.5, 2.0, 0});  // on the plane, moving up and sideways
  p.step(c, 1e-3);
  EXPECT_NEAR(p.s.v[1], 2.0 - kG * 1e-3, 1e-12);  // upward motion untouched
  EXPECT_NEAR(p.s.v[0], 0.5, 1e-12);               // no friction once separating
  EXPECT_GT(p.s.x[1], 0.0);
}

TEST(Colliders, MovingPlanePushesTheParticleWithIt) {
  const auto c = parse("colliders: [{type: plane, motion: {type: translate, velocity: [0, 1.5, 0]}}]");
  Particle p({0, 0, 0});
  for (int k = 0; k < 100; ++k) p.step(c, 1e-3);
  EXPECT_NEAR(p.s.v[1], 1.5, 1e-9);
  EXPECT_NEAR(p.s.x[1], 0.15, 1e-9);
}

TEST(Colliders, KeyframedMotionInterpolates) {
  const auto c = parse(
      "colliders: [{type: sphere, center: [0,0,0], radius: 1, motion: {type: keyframes, axis: [0,1,0], keys: ["
      "{t: 0, translate: [0,0,0], angle: 0}, {t: 2, translate: [2,0,0], angle: 1}]}}]");
  const auto& m = c.colliders()[0].motion;
  EXPECT_DOUBLE_EQ(m.displacement(1.0)[0], 1.0);
  EXPECT_DOUBLE_EQ(m.angle(1.0), 0.5);
  EXPECT_DOUBLE_EQ(m.linear_velocity(1.0)[0], 1.0);
  EXPECT_DOUBLE_EQ(m.spin(1.0), 0.5);
  EXPECT_DOUBLE_EQ(m.displacement(5.0)[0], 2.0);  // held after the last key
  EXPECT_DOUBLE_EQ(m.spin(5.0), 0.0);
}

TEST(Colliders, PinnedVerticesAreNeverMoved) {
  const auto c = parse("colliders: [{type: plane}]");
  loom::State s;
  s.resize(1);
  s.mass[0] = 1;
  s.x = {0, -0.5, 0};
  s.pin(0);
  c.resolve_contacts(s, 0.0, 1e-3);
  EXPECT_EQ(s.x[1], -0.5);
}

TEST(Colliders, BadInputNamesLineAndFix) {
  std::string e = error_of("colliders:\n  - type: sphere\n    center: [0, 0, 0]\n    radius: -1\n");
  EXPECT_NE(e.find("colliders.yaml:4"), std::string::npos) << e;
  EXPECT_NE(e.find("radius must be"), std::string::npos) << e;
  e = error_of("colliders: [{type: cube}]");
  EXPECT_NE(e.find("unknown value 'cube'"), std::string::npos) << e;
  EXPECT_NE(e.find("sphere, plane"), std::string::npos) << e;
  e = error_of("colliders: [{type: plane, motion: {type: rotate, axis: [0, 1, 0], angular_velocity: .nan}}]");
  EXPECT_NE(e.find("finite"), std::string::npos) << e;
  e = error_of("colliders: [{type: plane, motion: {type: translate, velocity: [0, .inf, 0]}}]");
  EXPECT_NE(e.find("finite"), std::string::npos) << e;
  e = error_of("colliders: [{type: plane, normal: [0, 0, 0]}]");
  EXPECT_NE(e.find("non-zero"), std::string::npos) << e;
  e = error_of("colliders: [{type: plane, friction: {static: 0.1, kinetic: 0.5}}]");
  EXPECT_NE(e.find("must not exceed"), std::string::npos) << e;
  e = error_of("colliders: [{type: sphere, center: [0,0,0], radius: 1, raduis: 2}]");
  EXPECT_NE(e.find("did you mean 'radius'"), std::string::npos) << e;
  e = error_of("colliders: {type: plane}");
  EXPECT_NE(e.find("must be a list"), std::string::npos) << e;
}

// Spheres and planes answer a cutoff query without the exact one where the vertex is certainly
// at least `cutoff` away (a bound without a square root): below the cutoff the result is the
// exact query's, bit for bit (distance, normal, surface velocity); above it a lower bound at or
// above the cutoff. Points uniformly in a box, and points placed at the offset surface + cutoff
// within a few ulp, where the bound must not skip a vertex the exact query puts below the cutoff.
TEST(Colliders, SphereAndPlaneCutoffQueryIsExactBelowTheCutoffAndALowerBoundAbove) {
  const auto set = parse(
      "colliders: [{type: sphere, center: [0.5, -0.35, -0.5], radius: 0.3, thickness: 0.004,"
      " motion: {type: rotate, axis: [0, 1, 0], angular_velocity: 2.0}},"
      " {type: plane, point: [0.1, -0.2, 0.3], normal: [0.3, 1, -0.2], thickness: 0.002,"
      " motion: {type: translate, velocity: [0.1, 0.2, 0.0]}}]");
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> U(-1.5, 1.5), A(-1.0, 1.0);
  int below = 0, above = 0, near = 0;
  for (const loom::Collider& c : set.colliders()) {
    const loom::Collider::Frame f = c.frame_at(0.37);
    for (const double cutoff : {0.0, 0.004, 0.05})
      for (int i = 0; i < 20000; ++i) {
        double p[3] = {U(rng), U(rng), U(rng)};
        if (i % 2 == 1) {   // on the cutoff surface, nudged by a few ulp either way
          double u[3] = {A(rng), A(rng), A(rng)};
          const double len = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
          if (c.shape == loom::Collider::Shape::Sphere) {
            for (int k = 0; k < 3; ++k) p[k] = f.center[k] + u[k] / len * (c.radius + c.thickness + cutoff);
          } else {   // a point of the plane + (thickness + cutoff) along the normal
            const double s = (p[0] - f.center[0]) * f.normal[0] + (p[1] - f.center[1]) * f.normal[1] +
                             (p[2] - f.center[2]) * f.normal[2];
            for (int k = 0; k < 3; ++k) p[k] += (c.thickness + cutoff - s) * f.normal[k];
          }
          for (int k = 0; k < 3; ++k) p[k] = std::nextafter(p[k], (i / 2) % 2 ? 10.0 : -10.0);
        }
        const loom::Collider::Contact e = c.query(f, p);
        const loom::Collider::Contact q = c.query(f, p, cutoff);
        if (std::abs(e.distance - cutoff) < 1e-12) ++near;
        if (e.distance < cutoff) {
          ++below;
          ASSERT_EQ(q.distance, e.distance) << c.name << " cutoff " << cutoff << " point " << i;
          for (int k = 0; k < 3; ++k) {
            ASSERT_EQ(q.normal[k], e.normal[k]);
            ASSERT_EQ(q.velocity[k], e.velocity[k]);
          }
        } else {
          ++above;
          ASSERT_GE(q.distance, cutoff) << c.name;
          ASSERT_LE(q.distance, e.distance) << c.name;
        }
      }
  }
  EXPECT_GT(below, 10000);   // both branches and the boundary are exercised
  EXPECT_GT(above, 10000);
  EXPECT_GT(near, 10000);
}
