#include "loom/section_specs.hpp"

#include <stdexcept>

#include "loom/self_collision.hpp"
#include "loom/simulation.hpp"

namespace loom {

const ParamSpec& scene_section_spec() {
  static const ParamSpec s = [] {
    ParamSpec s("scene", "top-level keys of a scene file (each section has its own table)");
    s.open_map("mesh").required().framework().help("the cloth's mesh: loom plugins --params mesh");
    s.open_map("material").required().framework().help("material plugin and its keys: loom plugins --params NAME");
    s.open_map("integrator").required().framework().help("integrator plugin, dt and substeps: loom plugins --params NAME");
    s.open_map("solver").no_default().framework().shown_type("string | map").help(
        "linear solver (implicit integrators): a name, a list of names (first available), or {type: ..., NAME: {...}}: "
        "loom plugins --params solver");
    s.integer("frames", 60).range(ParamRange::closed(0, 1e9)).framework().help("output frames to simulate");
    s.vec3("gravity", {0.0, -9.81, 0.0}).units("m/s^2").framework().help("gravitational acceleration");
    s.list("pins").framework().help(
        "pinned vertices: group names, {vertices: [...]}, {box: {min, max}}, with optional motion: loom plugins --params pins");
    s.list("mass_scale").framework().help(
        "per-vertex mass factors: [{vertices | group | box, factor: f}]: loom plugins --params mass_scale");
    s.number("initial_scale", 1.0).range(ParamRange::positive()).framework().help(
        "start with positions scaled about the centroid (rest shape unchanged)");
    s.vec3("initial_velocity", {0.0, 0.0, 0.0}).units("m/s").framework().help("initial velocity of every vertex");
    s.list("colliders").framework().help("planes, spheres, meshes the cloth collides with: loom plugins --params colliders");
    s.open_map("self_collision").no_default().framework().help("cloth-cloth contact: loom plugins --params self_collision");
    s.open_map("output").no_default().framework().help("files written by a run: loom plugins --params output");
    s.open_map("guard").no_default().framework().help("divergence guards: loom plugins --params guard");
    s.choice("backend", "cpu", {"cpu", "cuda"}).framework().help("execution backend");
    s.text("threads", "auto").framework().shown_type("auto | int").help(
        "OpenMP threads: auto (the usable cores) or a count (0 = auto)");
    s.text("description", "").no_default().framework().help("free text");
    s.text("name", "").no_default().framework().help("free text");
    s.open_map("render").no_default().framework().help("read by loom render: loom plugins --params gl");
    s.open_map("kawabata").no_default().framework().help("read by scripts/kawabata.py, not by a run");
    return s;
  }();
  return s;
}

const ParamSpec& mesh_section_spec() {
  static const ParamSpec s = [] {
    ParamSpec grid("grid", "a generated rectangular grid");
    grid.integer("nx", 32).required().range(ParamRange::closed(2, 20000)).help("vertices along the width");
    grid.integer("ny", 32).required().range(ParamRange::closed(2, 20000)).help("vertices along the height");
    grid.number("width", 1.0).range(ParamRange::positive()).units("m").help("size along the first axis (x)");
    grid.number("height", 1.0).range(ParamRange::positive()).units("m").help("size along the second axis (y or z)");
    grid.choice("plane", "xy", {"xy", "xz"}).help("the plane the grid lies in (xz: horizontal)");
    grid.choice("diagonals", "alternate", {"alternate", "uniform"}).help("how the quads are split into triangles");
    ParamSpec s("mesh", "the cloth's mesh: exactly one of grid or obj");
    s.map("grid", grid).no_default().framework().help("generate a grid");
    s.text("obj", "").no_default().framework().help("read a Wavefront OBJ file (relative to the scene file's folder)");
    s.number("scale", 1.0).range(ParamRange::positive()).framework().help("multiplies the OBJ's coordinates");
    return s;
  }();
  return s;
}

const ParamFields<OutputOptions>& output_section_fields() {
  static const ParamFields<OutputOptions> fields = [] {
    using O = OutputOptions;
    ParamFields<O> f("output", "files a run writes (loom run --out DIR sets dir)");
    f.text("dir", &O::dir).default_text("none (no files)").framework().help("output folder");
    f.flag("obj", &O::obj).framework().help("one OBJ per written frame");
    f.flag("stats", &O::stats).framework().help("stats.csv: energies, strain, cost per frame");
    f.integer("every", &O::every).range(ParamRange::closed(1, 1e9)).framework().help("write every n-th frame");
    f.flag("pc2", &O::pc2).framework().help("run.pc2 point cache beside rest.obj (Blender)");
    f.flag("uvs", &O::uvs).framework().help("OBJ frames carry texture coordinates (vt); ParaView frames the point data uv (meshes without UV seams)");
    f.flag("normals", &O::normals).framework().help("OBJ frames carry normals (vn)");
    f.flag("lossless", &O::lossless).framework().help("OBJ coordinates in full double precision");
    f.flag("vtk", &O::vtk).framework().help("ParaView frames (frame_NNNNN.vtu) and run.pvd");
    f.flag("velocities", &O::velocities).framework().help("per-vertex velocities in the .vtu frames / velocity.pc2");
    f.flag("restart", &O::restart).framework().help("restart.bin, the last complete frame's state (loom run --resume)");
    f.number("restart_interval", &O::restart_interval).range(ParamRange::closed(0, 1e9)).units("s").framework().help(
        "wall time between restart.bin writes (always after frame 0, the last frame and an early stop); 0: every frame");
    return f;
  }();
  return fields;
}

const ParamSpec& output_section_spec() { return output_section_fields().spec(); }

const ParamFields<GuardOptions>& guard_section_fields() {
  static const ParamFields<GuardOptions> fields = [] {
    using O = GuardOptions;
    ParamFields<O> f("guard", "divergence guards: the run stops with exit code 3 when one trips");
    f.number("max_velocity", &O::max_velocity).range(ParamRange::positive()).units("m/s").framework().help(
        "largest vertex speed");
    f.number("max_strain", &O::max_strain).range(ParamRange::positive()).framework().help(
        "largest element strain (relative), checked once per frame");
    f.integer("check_every", &O::check_every).range(ParamRange::closed(1, 1e9)).framework().help(
        "steps between the NaN / speed checks");
    return f;
  }();
  return fields;
}

const ParamSpec& guard_section_spec() { return guard_section_fields().spec(); }

const ParamSpec& self_collision_section_spec() {
  static const ParamSpec s = [] {
    const SelfCollision::Options d;
    ParamSpec s("self_collision", "cloth-cloth contact (docs/CONTACT.md)");
    s.number("thickness", 0.002).required().range(ParamRange::positive()).units("m").framework().help(
        "gap kept between layers of cloth (a quarter of the edge length or less)");
    s.number("friction", d.friction).range(ParamRange::at_least(0)).framework().help(
        "Coulomb coefficient between layers (0 = frictionless)");
    return s;
  }();
  return s;
}

const ParamSpec& solver_section_spec() {
  static const ParamSpec s = [] {
    ParamSpec s("solver", "solver: NAME, solver: [NAME, ...], or a mapping with type and one block of keys per solver "
                          "name (loom plugins --params NAME); blocks of other solvers may stay for --set solver.type=...");
    s.text("type", "").required().framework().shown_type("string | list").help(
        "a solver name, or a list of names: the first one available in this build (and backend) is used");
    return s;
  }();
  return s;
}

const ParamSpec& bending_section_spec() {
  static const ParamSpec s = [] {
    ParamSpec stiffness("stiffness");
    stiffness.number("weft", 0.0).required().range(ParamRange::nonnegative()).units("N m").help("rigidity across the weft");
    stiffness.number("warp", 0.0).required().range(ParamRange::nonnegative()).units("N m").help("rigidity across the warp");
    stiffness.number("bias", 0.0).default_text("(weft + warp) / 2").range(ParamRange::nonnegative()).units("N m").help(
        "rigidity at 45 degrees");
    ParamSpec s("bending", "material.bending: hinge bending added to any material (docs/plugins/bending.md)");
    s.number_or_map("stiffness", 0.0, std::move(stiffness)).required().range(ParamRange::nonnegative()).units("N m")
        .framework().help("bending rigidity B: one number (isotropic), or {weft, warp, bias} (needs the mesh's uvs)");
    s.choice("jacobian", "gauss_newton", {"gauss_newton", "exact"}).framework().help(
        "hinge Jacobian: Gauss-Newton (PSD) or the exact one");
    s.choice("non_manifold", "error", {"error", "skip"}).framework().help(
        "an edge shared by more than two triangles: refuse the mesh, or give it no hinge");
    s.number("weft_angle", 0.0).range(ParamRange::closed(-2 * 3.14159265358979323846, 2 * 3.14159265358979323846))
        .units("rad").framework().help("angle of the weft direction from the texture's u axis");
    return s;
  }();
  return s;
}

namespace {

// The keys that select vertices (select_vertices, loom/pins.hpp): pins and mass_scale entries.
void declare_selection(ParamSpec& s) {
  ParamSpec box("box");
  box.vec3("min", {0, 0, 0}).required().units("m").help("lower corner (the mesh's rest coordinates)");
  box.vec3("max", {0, 0, 0}).required().units("m").help("upper corner");
  s.text("group", "").no_default().framework().help(
      "a named group: top_corners, top_edge, left_corners, left_edge, bottom_corners, bottom_edge, right_edge, corners");
  s.list("vertices").framework().help("vertex indices, numbered from 0");
  s.map("box", std::move(box)).no_default().framework().help("the vertices inside an axis-aligned box");
}

// motion: of a pin group (with `center`) or of a collider (loom/collider.hpp, RigidMotion).
ParamSpec motion_fields(bool pin) {
  ParamSpec m("motion");
  m.choice("type", "fixed", {"fixed", "translate", "rotate", "keyframes"}).help("prescribed rigid motion");
  m.vec3("velocity", {0, 0, 0}).required().units("m/s").help("translate: constant velocity");
  m.vec3("axis", {0, 1, 0}).help("rotate, keyframes: rotation axis (normalised)");
  m.number("angular_velocity", 0.0).units("rad/s").help("rotate: angular velocity about the axis");
  m.choice("interpolation", "linear", {"linear", "smooth"}).help("keyframes: between keys (smooth: a quintic ease, zero velocity and acceleration at each key)");
  m.list("keys").help("keyframes: [{t, translate, angle}] in time order (loom plugins --params motion_keys)");
  if (pin)
    m.vec3("center", {0, 0, 0}).default_text("the group's centroid").units("m").help(
        "rotate, keyframes: a point on the rotation axis");
  return m;
}

}  // namespace

const ParamSpec& pin_entry_spec() {
  static const ParamSpec s = [] {
    ParamSpec s("pins", "an entry of pins: a group name, or a mapping (vertices selected by group, vertices and box "
                        "together); docs/SCENES.md");
    s.text("name", "").default_text("the group's name, else pinK").framework().help(
        "the group's name (stats.csv reaction columns): letters, digits, '_' or '-'");
    declare_selection(s);
    s.map("motion", motion_fields(true)).no_default("fixed").framework().help("the pinned vertices' prescribed motion");
    return s;
  }();
  return s;
}

const ParamSpec& mass_scale_entry_spec() {
  static const ParamSpec s = [] {
    ParamSpec s("mass_scale", "an entry of mass_scale: the selected vertices' masses are multiplied by factor "
                              "(factors of entries that select a vertex multiply)");
    s.number("factor", 1.0).range(ParamRange::positive()).framework().help("mass multiplier");
    declare_selection(s);
    return s;
  }();
  return s;
}

const ParamSpec& collider_entry_spec() {
  static const ParamSpec s = [] {
    ParamSpec friction("friction");
    friction.number("static", 0.0).range(ParamRange::nonnegative()).help("static Coulomb coefficient");
    friction.number("kinetic", 0.0).default_text("static").range(ParamRange::nonnegative()).help(
        "kinetic Coulomb coefficient (<= static)");
    ParamSpec s("colliders", "an entry of colliders: a sphere, plane or mesh the cloth cannot enter (docs/CONTACT.md)");
    s.choice("type", "plane", {"sphere", "plane", "mesh"}).required().framework().help("the collider's shape");
    s.text("name", "").default_text("TYPE K").framework().help("label in messages and stats");
    s.vec3("center", {0, 0, 0}).required().units("m").framework().help("sphere: centre");
    s.number("radius", 1.0).required().range(ParamRange::positive()).units("m").framework().help("sphere: radius");
    s.vec3("point", {0, 0, 0}).units("m").framework().help("plane: a point on the plane");
    s.vec3("normal", {0, 1, 0}).framework().help("plane: the side the cloth stays on (normalised)");
    s.text("obj", "").required().framework().help("mesh: a triangle mesh (OBJ, relative to the scene file's folder)");
    s.number("scale", 1.0).range(ParamRange::positive()).framework().help("mesh: multiplies the OBJ's coordinates");
    s.vec3("offset", {0, 0, 0}).units("m").framework().help("mesh: added to the scaled coordinates");
    s.vec3("pivot", {0, 0, 0}).default_text("the mesh's box centre").units("m").framework().help(
        "mesh: the point its motion rotates about");
    s.number("thickness", 0.0).range(ParamRange::nonnegative()).units("m").framework().help(
        "contact offset: the cloth stays this far outside the surface");
    s.number_or_map("friction", 0.0, std::move(friction)).range(ParamRange::nonnegative()).framework().help(
        "Coulomb coefficient, or {static, kinetic}");
    s.map("motion", motion_fields(false)).no_default("fixed").framework().help("the collider's prescribed rigid motion");
    return s;
  }();
  return s;
}

const ParamSpec& motion_key_spec() {
  static const ParamSpec s = [] {
    ParamSpec s("motion_keys", "an entry of motion.keys (type: keyframes) of a pin group or a collider");
    s.number("t", 0.0).required().units("s").framework().help("time of the key (increasing)");
    s.vec3("translate", {0, 0, 0}).units("m").framework().help("displacement at t");
    s.number("angle", 0.0).units("rad").framework().help("rotation about the motion's axis at t");
    return s;
  }();
  return s;
}

const ParamSpec& study_combo_spec() {
  static const ParamSpec s = [] {
    ParamSpec s("study_combos", "an entry of a study's combos (and of stability.combos)");
    s.text("name", "").required().framework().help("the combo's name in the tables");
    s.open_map("set").framework().help("--set overrides of the scene: {dotted.key: value, ...}");
    return s;
  }();
  return s;
}

const ParamSpec& stability_section_spec() {
  static const ParamSpec s = [] {
    ParamSpec sweep("sweep");
    sweep.text("key", "").required().help("the swept scene key (dotted, e.g. material.stiffness)");
    sweep.list("values").required().help("its values, one atlas column each");
    ParamSpec s("stability", "a study file's stability: section, read by loom study --stability");
    s.number("horizon", 0.5).range(ParamRange::positive()).units("s").framework().help(
        "simulated time a stable run must reach");
    s.number("h_min", 1e-7).range(ParamRange::positive()).units("s").framework().help("smallest step tried");
    s.number("h_max", 0.05).range(ParamRange::positive()).units("s").framework().help("largest step tried");
    s.integer("bisections", 10).range(ParamRange::closed(1, 40)).framework().help("bisection steps per combo");
    s.number("max_strain", 1.0).range(ParamRange::positive()).framework().help("a larger strain counts as unstable");
    s.number("max_seconds_per_run", 60.0).range(ParamRange::positive()).units("s").framework().help(
        "a run that takes longer is stopped (and not counted as stable)");
    s.list("combos").required().framework().help("[{name, set}] (loom plugins --params study_combos)");
    s.map("sweep", std::move(sweep)).no_default().framework().help("a scene key swept over values");
    return s;
  }();
  return s;
}

const ParamSpec& study_file_spec() {
  static const ParamSpec s = [] {
    ParamSpec steps("steps");
    steps.number("h0", 1e-3).range(ParamRange::positive()).units("s").help("largest step");
    steps.integer("levels", 4).range(ParamRange::closed(1, 20)).help("steps h0 / 2^k, k = 0 .. levels-1");
    ParamSpec reference("reference");
    reference.text("integrator", "rk4").help("the reference run's integrator");
    reference.number("dt", 1e-3 / 256).default_text("h0 / 2^(levels + 4)").range(ParamRange::positive()).units("s")
        .help("the reference run's step");
    reference.open_map("set").help("more --set overrides of the reference run: {dotted.key: value}");
    ParamSpec s("study", "a study file (loom study SCENE STUDY): work-precision combos against a reference");
    s.text("description", "").no_default().framework().help("free text");
    s.list("times").required().units("s").framework().help("simulated times at which errors are measured (increasing)");
    s.map("steps", std::move(steps)).required().framework().help("the ladder of steps");
    s.map("reference", std::move(reference)).no_default("rk4 at h0 / 2^(levels + 4)").framework().help(
        "the reference run");
    s.number("max_seconds_per_run", 300.0).range(ParamRange::positive()).units("s").framework().help(
        "a run that takes longer is stopped");
    s.number("max_strain", 1.0).range(ParamRange::positive()).framework().help("a larger strain counts as diverged");
    s.list("combos").required().framework().help("[{name, set}] (loom plugins --params study_combos)");
    s.open_map("stability").no_default().framework().help("read by loom study --stability: loom plugins --params stability");
    return s;
  }();
  return s;
}

const std::vector<std::pair<std::string, const ParamSpec*>>& framework_section_specs() {
  static const std::vector<std::pair<std::string, const ParamSpec*>> all = {
      {"scene", &scene_section_spec()},           {"mesh", &mesh_section_spec()},
      {"material", &material_section_spec()},     {"integrator", &integrator_section_spec()},
      {"solver", &solver_section_spec()},         {"bending", &bending_section_spec()},
      {"pins", &pin_entry_spec()},                {"mass_scale", &mass_scale_entry_spec()},
      {"colliders", &collider_entry_spec()},      {"motion_keys", &motion_key_spec()},
      {"self_collision", &self_collision_section_spec()},
      {"output", &output_section_spec()},         {"guard", &guard_section_spec()},
      {"render", &render_section_spec()},         {"study", &study_file_spec()},
      {"study_combos", &study_combo_spec()},      {"stability", &stability_section_spec()}};
  return all;
}

const ParamSpec* framework_section_spec(const std::string& name) {
  for (const auto& [n, s] : framework_section_specs())
    if (n == name) return s;
  return nullptr;
}

Params with_section_spec(const Params& p, const std::string& name) {
  const ParamSpec* spec = framework_section_spec(name);
  if (!spec) throw std::logic_error("no framework section spec named '" + name + "'");
  return p.with_spec(spec);
}

}  // namespace loom
