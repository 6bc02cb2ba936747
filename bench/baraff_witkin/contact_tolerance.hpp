// What the filtered PCG's tolerance costs in accuracy on scenes with contact (issue 15): one
// contact scene run through the plugin loader (as the CLI builds it) with `filtered_pcg` at a
// given tolerance and preconditioner, and the quantities that compare a run against the same
// scene solved at tolerance 1e-10 (the solve error) and at h/2 (the time-discretisation error):
// final positions, total energy, the deepest penetration of a vertex into the collider's true
// surface (not the offset one) and the most intersecting triangle pairs seen in any sampled step
// (loom::count_intersecting_pairs, exact and independent of the collision code).
// Shared by bench_bw_tolerance_contact (the study) and tests/bw_tolerance (its small check).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "loom/intersection_check.hpp"
#include "loom/registry.hpp"
#include "loom/scene.hpp"
#include "loom/simulation.hpp"

namespace loom::tolerance_study {

/// A contact scene: the YAML without `integrator:` and `solver:` (added per run), the step size
/// and the number of steps of the reference run, the cloth width (error scale) and the collider
/// geometry the penetration is measured against (a sphere when radius > 0, else the plane y = plane_y
/// when has_plane, else none). Pins with motions are part of the YAML.
struct ContactScene {
  std::string name;
  std::string yaml;
  double dt = 2e-3;
  int steps = 100;
  double width = 1.0;
  double kang_cho = 0.001;  ///< integrator's kang_cho_damping (< 0: the key is left out)
  double sphere_center[3] = {0, 0, 0};
  double sphere_radius = 0;
  bool has_plane = false;
  double plane_y = 0;
  int sample_every = 10;  ///< steps between intersection counts
};

/// The end state of one run and what was seen on the way.
struct RunResult {
  std::vector<double> x;        ///< final positions
  double iterations_per_step = 0;
  double energy = 0;            ///< kinetic + gravitational + elastic at the end (J)
  double max_penetration = 0;   ///< deepest vertex inside the collider's surface, any step (m; 0 = none)
  int max_intersections = 0;    ///< most intersecting non-adjacent triangle pairs in a sampled step
};

inline double depth_inside(const ContactScene& sc, const std::vector<double>& x) {
  double worst = 0;
  const std::size_t nv = x.size() / 3;
  for (std::size_t i = 0; i < nv; ++i) {
    if (sc.sphere_radius > 0) {
      const double dx = x[3 * i] - sc.sphere_center[0], dy = x[3 * i + 1] - sc.sphere_center[1],
                   dz = x[3 * i + 2] - sc.sphere_center[2];
      worst = std::max(worst, sc.sphere_radius - std::sqrt(dx * dx + dy * dy + dz * dz));
    }
    if (sc.has_plane) worst = std::max(worst, sc.plane_y - x[3 * i + 1]);
  }
  return worst;
}

/// The scene built as the CLI builds it, with filtered_pcg at `tolerance` and `preconditioner`
/// (block_jacobi | sa_amg), one thread (the result does not depend on it, but the thread
/// controller of `threads: auto` would make runs differ by the rounding of a switch).
inline std::unique_ptr<Simulation> build(const ContactScene& sc, double tolerance, const std::string& preconditioner,
                                         double dt, PluginLoader& loader) {
  char tol[64], h[64];
  std::snprintf(tol, sizeof tol, "%.17g", tolerance);
  std::snprintf(h, sizeof h, "%.17g", dt);
  const std::string damping = sc.kang_cho >= 0 ? ", kang_cho_damping: " + std::to_string(sc.kang_cho) : "";
  const std::string yaml = sc.yaml + "integrator: {type: baraff_witkin, dt: " + h + ", substeps: 1" + damping + "}\n" +
                           "solver: {type: filtered_pcg, filtered_pcg: {tolerance: " + tol +
                           ", max_iterations: 100000, preconditioner: " + preconditioner + "}}\n" + "threads: 1\n";
  return Simulation::from_string(yaml, "<" + sc.name + ">", std::string(LOOM_SOURCE_DIR) + "/scenes", {}, loader);
}

/// Runs `sc` for `steps` steps of `dt` (see build()).
inline RunResult run(const ContactScene& sc, double tolerance, const std::string& preconditioner, double dt, int steps) {
  Registry registry;
  PluginLoader loader{registry};
  auto sim = build(sc, tolerance, preconditioner, dt, loader);
  RunResult r;
  const long long it0 = sim->linear_iterations();
  for (int k = 1; k <= steps; ++k) {
    sim->step();
    const std::vector<double>& x = sim->scene().state.x;
    r.max_penetration = std::max(r.max_penetration, depth_inside(sc, x));
    if (k % sc.sample_every == 0 || k == steps)
      r.max_intersections =
          std::max(r.max_intersections, static_cast<int>(count_intersecting_pairs(sim->scene().mesh, x)));
  }
  r.iterations_per_step = static_cast<double>(sim->linear_iterations() - it0) / steps;
  const Simulation::FrameStats fs = sim->measure(0);
  r.energy = fs.kinetic + fs.gravitational + fs.elastic;
  r.x = sim->scene().state.x;
  return r;
}

/// RMS and largest vertex distance between two position sets, over `width`.
struct Distance {
  double rms = 0, max = 0;
};
inline Distance distance(const std::vector<double>& a, const std::vector<double>& b, double width) {
  Distance d;
  double s = 0;
  const std::size_t nv = a.size() / 3;
  for (std::size_t i = 0; i < nv; ++i) {
    double q = 0;
    for (int c = 0; c < 3; ++c) q += (a[3 * i + c] - b[3 * i + c]) * (a[3 * i + c] - b[3 * i + c]);
    s += q;
    d.max = std::max(d.max, std::sqrt(q));
  }
  d.rms = std::sqrt(s / static_cast<double>(nv)) / width;
  d.max /= width;
  return d;
}

/// The reference pair (tolerance 1e-10 at h and at h/2) and a run at a looser tolerance.
struct Study {
  RunResult ref, half, run;
  Distance solve_err, time_err;  ///< run vs ref; ref vs half
  double energy_solve_err = 0, energy_time_err = 0;  ///< |E(run) - E(ref)|, |E(ref) - E(half)| (J)
};

inline Study compare(const ContactScene& sc, const RunResult& ref, const RunResult& half, const RunResult& run) {
  Study s{ref, half, run, {}, {}, 0, 0};
  s.solve_err = distance(run.x, ref.x, sc.width);
  s.time_err = distance(ref.x, half.x, sc.width);
  s.energy_solve_err = std::abs(run.energy - ref.energy);
  s.energy_time_err = std::abs(ref.energy - half.energy);
  return s;
}

/// Local (one-step) errors along the 1e-10 trajectory, free of the divergence of nearby
/// trajectories that contact and folding amplify over a run: every step starts the run at
/// `tolerance` (B) and the 1e-10 run at h/2 (C, two steps) from the state (x, v, time) of the
/// 1e-10 run at h (A), and compares their ends with A's. Per step the RMS vertex distance over
/// the width is taken; the counters are its mean and largest value over the steps, and the
/// ratio solve / time-discretisation of the means and the largest per-step ratio.
struct LocalErrors {
  double mean_solve = 0, max_solve = 0, mean_time = 0, max_time = 0, max_ratio = 0;
  double iterations_per_step = 0;
};
inline LocalErrors local_errors(const ContactScene& sc, double tolerance, const std::string& preconditioner, int steps) {
  Registry registry;
  PluginLoader loader{registry};
  auto a = build(sc, 1e-10, "sa_amg", sc.dt, loader);
  auto b = build(sc, tolerance, preconditioner, sc.dt, loader);
  auto c = build(sc, 1e-10, "sa_amg", 0.5 * sc.dt, loader);
  LocalErrors e;
  long long its = 0;
  for (int k = 0; k < steps; ++k) {
    for (Simulation* s : {b.get(), c.get()}) {
      s->scene().state.x = a->scene().state.x;
      s->scene().state.v = a->scene().state.v;
      s->scene().state.time = a->scene().state.time;
    }
    const long long it0 = b->linear_iterations();
    a->step();
    b->step();
    c->step();
    c->step();
    its += b->linear_iterations() - it0;
    const double es = distance(b->scene().state.x, a->scene().state.x, sc.width).rms;
    const double et = distance(c->scene().state.x, a->scene().state.x, sc.width).rms;
    e.mean_solve += es / steps;
    e.mean_time += et / steps;
    e.max_solve = std::max(e.max_solve, es);
    e.max_time = std::max(e.max_time, et);
    if (et > 0) e.max_ratio = std::max(e.max_ratio, es / et);
  }
  e.iterations_per_step = static_cast<double>(its) / steps;
  return e;
}

// ---- The scenes of the study (NUMERICS.md 3.6, "The tolerance on contact scenes") ----

/// A scene named `name` on an n x n grid `size` m square (as the YAML writes it) in `plane`
/// (xy | xz), `rest` the YAML after the mesh, run for `steps` steps of `dt`.
inline ContactScene grid_scene(const std::string& name, int n, const std::string& size, const std::string& plane,
                               const std::string& rest, double dt, int steps) {
  ContactScene sc;
  sc.name = name;
  sc.yaml = "mesh: {grid: {nx: " + std::to_string(n) + ", ny: " + std::to_string(n) + ", width: " + size +
            ", height: " + size + ", plane: " + plane + "}}\n" + rest;
  sc.dt = dt;
  sc.steps = steps;
  return sc;
}

/// The penetration is measured against a sphere of `radius` centred at (x, y, z).
inline void measure_sphere(ContactScene& sc, double x, double y, double z, double radius) {
  sc.sphere_center[0] = x;
  sc.sphere_center[1] = y;
  sc.sphere_center[2] = z;
  sc.sphere_radius = radius;
}

/// The shipped wool (materials/wool.yaml) as the YAML's material.
inline std::string wool_material() {
  return "material: {type: gnatv, material_file: " + std::string(LOOM_SOURCE_DIR) + "/materials/wool.yaml}\n";
}

/// The drape of bench_baraff_witkin: an n x n cloth, 1 m square, released flat in contact with
/// the top of a ball (radius 0.3 m, thickness 1 mm, friction 0.5/0.4), h = 2 ms.
/// `material` is the material mapping's body, e.g. "type: gnatv, fabric: 11oz-black-denim".
inline ContactScene drape(int n, const std::string& material, const std::string& name, int steps) {
  ContactScene sc = grid_scene(name, n, "1.0", "xz",
                               "material: {" + material + "}\n"
                               "colliders: [{type: sphere, center: [0.5, -0.3005, -0.5], radius: 0.3, thickness: 0.001, "
                               "friction: {static: 0.5, kinetic: 0.4}}]\n"
                               "gravity: [0, -9.81, 0]\n",
                               2e-3, steps);
  measure_sphere(sc, 0.5, -0.3005, -0.5, 0.3);
  return sc;
}

/// Moving pins: an n x n wool cloth, 1 m square hanging in the xy plane from its two top corners,
/// which turn about the vertical axis through the top edge's centre at 3 rad/s (the corners
/// move at 1.5 m/s and twist the cloth), h = 5 ms.
inline ContactScene moving_pins(int n, int steps) {
  ContactScene sc = grid_scene("pins" + std::to_string(n), n, "1.0", "xy",
                               wool_material() +
                                   "pins: [{group: top_corners, motion: {type: rotate, axis: [0, 1, 0], center: [0.5, 1.0, 0], "
                                   "angular_velocity: 3.0}}]\n"
                                   "gravity: [0, -9.81, 0]\n",
                               5e-3, steps);
  sc.kang_cho = 0.01;
  return sc;
}

/// Self-collision under Baraff-Witkin: the folding cloth of tests/baraff_witkin (a 0.4 m square
/// standing on its edge collapses in folds onto a plane; mass_spring, self_collision thickness
/// 4 mm, the springs of the implicit self-contact in the solve), n x n, h = 2 ms.
inline ContactScene fold(int n, int steps) {
  ContactScene sc = grid_scene("fold" + std::to_string(n), n, "0.4", "xy",
                               "material: {type: mass_spring, stencil: structural_shear_bend, stiffness: {structural: 300, shear: 300, "
                               "bend: 0.2}, damping: 0.01, density: 0.2}\n"
                               "gravity: [0, -9.81, 1.5]\n"
                               "colliders: [{type: plane, point: [0, -0.01, 0], normal: [0, 1, 0], friction: 0.8}]\n"
                               "self_collision: {thickness: 0.004, friction: 0.3}\n",
                               2e-3, steps);
  sc.width = 0.4;
  sc.kang_cho = -1;
  sc.has_plane = true;
  sc.plane_y = -0.01;
  return sc;
}

/// The shipped draped-ball scene (scenes/draped_ball_gnatv_bw.yaml) at n x n: wool on a ball
/// spinning at 2 rad/s, friction, self-collision (thickness 4 mm), h = 2 ms.
inline ContactScene spinning_ball_self(int n, int steps) {
  ContactScene sc = grid_scene("ball_self" + std::to_string(n), n, "1.0", "xz",
                               wool_material() +
                                   "colliders: [{type: sphere, center: [0.5, -0.35, -0.5], radius: 0.3, thickness: 0.004, "
                                   "friction: {static: 0.5, kinetic: 0.4}, motion: {type: rotate, axis: [0, 1, 0], angular_velocity: 2.0}}]\n"
                                   "self_collision: {thickness: 0.004, friction: 0.3}\n"
                                   "gravity: [0, -9.81, 0]\n",
                               2e-3, steps);
  measure_sphere(sc, 0.5, -0.35, -0.5, 0.3);
  return sc;
}

}  // namespace loom::tolerance_study
