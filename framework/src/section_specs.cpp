#include "loom/section_specs.hpp"

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
        "linear solver (implicit integrators): a name, a list of names (first available), or {type: ..., NAME: {...}}");
    s.integer("frames", 60).range(ParamRange::closed(0, 1e9)).framework().help("output frames to simulate");
    s.vec3("gravity", {0.0, -9.81, 0.0}).units("m/s^2").framework().help("gravitational acceleration");
    s.list("pins").framework().help(
        "pinned vertices: group names, {vertices: [...]}, {box: {min, max}}, with optional motion (docs/SCENES.md)");
    s.list("mass_scale").framework().help("per-vertex mass factors: [{vertices | group | box, factor: f}]");
    s.number("initial_scale", 1.0).range(ParamRange::positive()).framework().help(
        "start with positions scaled about the centroid (rest shape unchanged)");
    s.vec3("initial_velocity", {0.0, 0.0, 0.0}).units("m/s").framework().help("initial velocity of every vertex");
    s.list("colliders").framework().help("planes, spheres, boxes, meshes the cloth collides with (docs/CONTACT.md)");
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

const ParamSpec& output_section_spec() {
  static const ParamSpec s = [] {
    const OutputOptions d;
    ParamSpec s("output", "files a run writes (loom run --out DIR sets dir)");
    s.text("dir", "").default_text("none (no files)").framework().help("output folder");
    s.flag("obj", d.obj).framework().help("one OBJ per written frame");
    s.flag("stats", d.stats).framework().help("stats.csv: energies, strain, cost per frame");
    s.integer("every", d.every).range(ParamRange::closed(1, 1e9)).framework().help("write every n-th frame");
    s.flag("pc2", d.pc2).framework().help("run.pc2 point cache beside rest.obj (Blender)");
    s.flag("uvs", d.uvs).framework().help("OBJ frames carry texture coordinates (vt)");
    s.flag("normals", d.normals).framework().help("OBJ frames carry normals (vn)");
    s.flag("lossless", d.lossless).framework().help("OBJ coordinates in full double precision");
    s.flag("vtk", d.vtk).framework().help("ParaView frames (frame_NNNNN.vtu) and run.pvd");
    s.flag("velocities", d.velocities).framework().help("per-vertex velocities in the .vtu frames / velocity.pc2");
    s.flag("restart", d.restart).framework().help("restart.bin after every frame (loom run --resume)");
    return s;
  }();
  return s;
}

const ParamSpec& guard_section_spec() {
  static const ParamSpec s = [] {
    const GuardOptions d;
    ParamSpec s("guard", "divergence guards: the run stops with exit code 3 when one trips");
    s.number("max_velocity", d.max_velocity).range(ParamRange::positive()).units("m/s").framework().help(
        "largest vertex speed");
    s.number("max_strain", d.max_strain).range(ParamRange::positive()).framework().help(
        "largest element strain (relative), checked once per frame");
    s.integer("check_every", d.check_every).range(ParamRange::closed(1, 1e9)).framework().help(
        "steps between the NaN / speed checks");
    return s;
  }();
  return s;
}

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

const std::vector<std::pair<std::string, const ParamSpec*>>& framework_section_specs() {
  static const std::vector<std::pair<std::string, const ParamSpec*>> all = {
      {"scene", &scene_section_spec()},           {"mesh", &mesh_section_spec()},
      {"material", &material_section_spec()},     {"integrator", &integrator_section_spec()},
      {"output", &output_section_spec()},         {"guard", &guard_section_spec()},
      {"self_collision", &self_collision_section_spec()}, {"render", &render_section_spec()}};
  return all;
}

const ParamSpec* framework_section_spec(const std::string& name) {
  for (const auto& [n, s] : framework_section_specs())
    if (n == name) return s;
  return nullptr;
}

}  // namespace loom
