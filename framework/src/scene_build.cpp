// The stages of Simulation::build (scene_build.hpp): each reads one part of the scene file.
#include "scene_build.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>

#include "loom/bending.hpp"
#include "loom/fabric_library.hpp"
#include "loom/memory_estimate.hpp"
#include "loom/param_spec.hpp"
#include "loom/pins.hpp"
#include "loom/section_specs.hpp"
#include "loom/text.hpp"

namespace fs = std::filesystem;

namespace loom::scene_build {

namespace {

// A vector of 3 finite numbers (initial_velocity, gravity); `what` starts the messages.
std::vector<double> finite3(const Params& p, const std::string& what, const std::string& example) {
  const auto v = p.as_doubles();
  if (v.size() != 3) p.fail(what + "needs 3 components, " + example + ".");
  for (double c : v)
    if (!std::isfinite(c)) p.fail(what + "components must be finite numbers.");
  return v;
}

// Optional section `name` of the scene with its spec attached (section_specs.cpp); when given
// it must be a mapping (`example` shows one).
Params optional_section(const Params& root, const std::string& name, const std::string& example) {
  const Params p = with_section_spec(root.child(name), name);
  if (p.valid() && !p.is_map()) p.fail("must be a mapping like " + example + ".");
  return p;
}

// `make` builds a plugin of `kind` named `name` from `section`; when it refuses a key that other
// plugins of the kind declare (a scene whose type was switched, e.g. by --set
// integrator.type=rk4, keeps the keys of the plugin before), the error names those plugins and
// how to drop the key. Their modules are loaded only then.
template <class Make>
auto naming_key_owners(PluginKind kind, const std::string& name, const Params& section, PluginLoader& loader,
                       Make&& make) {
  try {
    return make();
  } catch (const InputError& e) {
    const std::string msg = e.what();
    for (const auto& k : section.keys()) {
      if (msg.find("unknown key '" + k + "'") == std::string::npos) continue;
      std::string owners;
      for (const auto& other : loader.names(kind)) {
        if (other == name) continue;
        try {
          loader.ensure(kind, other);
        } catch (const InputError&) {
          continue;  // a module that does not load names nothing
        }
        const ParamSpec* spec = loader.registry().params(kind, other);
        if (spec && spec->find(k)) owners += (owners.empty() ? "'" : "', '") + other;
      }
      if (owners.empty()) break;
      const std::string dotted = section.path().empty() ? k : section.path() + "." + k;
      const std::string whose = " '" + k + "' is a key of " + to_string(kind) + " " + owners + "', not of '" + name + "'";
      if (msg.rfind("--set ", 0) == 0) throw InputError(msg + whose + ". Fix: drop that --set.");
      throw InputError(msg + whose + ": a scene switched to another " + to_string(kind) +
                       " keeps the keys of the one before. Fix: remove it from the scene, or run with --set " + dotted +
                       "=null.");
    }
    throw;
  }
}

}  // namespace

void apply_overrides(Params& root, const std::vector<std::string>& overrides) {
  for (const auto& o : overrides) {
    const auto eq = o.find('=');
    if (eq == std::string::npos || eq == 0)
      throw InputError("--set " + o + ": expected key=value, e.g. --set integrator.dt=0.0005");
    root.set_path(o.substr(0, eq), o.substr(eq + 1));
  }
}

std::string memory_line(const Params& root, long long vertices) {
  MemoryCombo combo;
  combo.vertices = vertices;
  auto scalar = [](const Params& p) { return p.valid() && p.is_scalar() ? p.as_string() : std::string(); };
  const Params integ = root.child("integrator");
  if (integ.is_map()) combo.integrator = scalar(integ.child("type"));
  const Params solver = root.child("solver");
  if (solver.valid()) {
    Params type = solver.is_map() ? solver.child("type") : solver;
    combo.solver = type.is_sequence() && type.size() > 0 ? scalar(type.at(0)) : scalar(type);
    if (solver.is_map() && solver.child("eigen_pcg").is_map())
      combo.sa_amg = scalar(solver.child("eigen_pcg").child("preconditioner")) == "sa_amg";
  }
  const Params mat = root.child("material");
  combo.bending = mat.is_map() && (mat.has("bending") || mat.has("fabric"));
  combo.self_collision = root.has("self_collision");
  const MemoryEstimate est = estimate_run_memory(combo);
  const auto machine = machine_memory_bytes();
  std::string line = "memory:     about " + format_bytes(est.bytes) + " at the peak (" + est.basis + ", " +
                     std::to_string(vertices) + " vertices)" +
                     (machine ? "; this machine has " + format_bytes(*machine) : std::string("; machine memory unknown"));
  if (machine && est.bytes > *machine)
    root.child("mesh").fail("this run needs about " + format_bytes(est.bytes) + " of memory (" + est.basis + ", " +
                            std::to_string(vertices) + " vertices), more than this machine's " +
                            format_bytes(*machine) + ". Fix: use a coarser mesh (fewer vertices), an iterative "
                            "solver instead of a direct one, or a machine with more memory.");
  return line;
}

Mesh mesh(const Params& root, const std::string& base_dir, const std::function<void(long long)>& before_allocating) {
  Mesh m;
  const Params mesh = with_section_spec(root.child("mesh"), "mesh");  // its keys: section_specs.cpp
  if (!mesh.valid()) root.fail("missing 'mesh' section. Fix: add mesh: {grid: {nx: 32, ny: 32, width: 1, height: 1}} or mesh: {obj: file.obj}.");
  if (!mesh.is_map()) mesh.fail("must be a mapping with 'grid' or 'obj'.");
  const bool has_grid = mesh.has("grid"), has_obj = mesh.has("obj");
  if (has_grid == has_obj) mesh.fail("give exactly one of 'grid' or 'obj'.");
  if (has_grid) {
    const ParamReader g = ParamReader(mesh, mesh_section_spec()).section("grid");
    if (!g.params().is_map()) g.params().fail("must be a mapping like {nx: 32, ny: 32, width: 1.0, height: 1.0}.");
    // nx and ny are checked together (one message for both); the spec declares the same range.
    const auto nx = g.params().require_int("nx"), ny = g.params().require_int("ny");
    if (nx < 2 || ny < 2 || nx > 20000 || ny > 20000) g.params().fail("nx and ny must be in [2, 20000] (got " + std::to_string(nx) + " x " + std::to_string(ny) + ").");
    const double w = g.number("width"), h = g.number("height");
    const std::string plane = g.text("plane");
    const std::string diag = g.text("diagonals");
    g.params().check_unused();
    before_allocating(static_cast<long long>(nx) * ny);  // before the grid allocates anything
    m = make_grid(static_cast<Index>(nx), static_cast<Index>(ny), w, h,
                  plane == "xy" ? GridPlane::XY : GridPlane::XZ, diag == "alternate");
  } else {
    Params o = mesh.child("obj");
    const std::string file = resolve_path(base_dir, o.as_string());
    if (!fs::exists(file)) o.fail("OBJ file '" + file + "' not found. Fix: paths are relative to the scene file's folder.");
    m = read_obj(file);
    before_allocating(static_cast<long long>(m.num_vertices()));
    const double scale = ParamReader(mesh, mesh_section_spec()).number("scale");
    for (double& c : m.positions) c *= scale;
  }
  mesh.check_unused();
  return m;
}

std::string material(const Params& root, Scene& sc, PluginLoader& loader) {
  const Params mat = with_section_spec(root.child("material"), "material");  // type, fabric, bending (+ the plugin's keys)
  if (!mat.is_map()) root.fail("missing 'material' section. Fix: add material: {type: mass_spring, ...}.");
  const std::string material_name = mat.require_string("type");
  try {
    loader.ensure(PluginKind::Material, material_name);
  } catch (const InputError& e) {
    mat.child("type").fail(e.what());
  }
  try {
    loader.ensure_backend(sc.backend);
  } catch (const InputError& e) {
    root.child("backend").fail(e.what());
  }
  // A material describes the cloth (masses, elements, curves); execution backends read that
  // description, so a material without a backend-specific version is used as is.
  const bool material_on_backend = loader.registry().has(PluginKind::Material, material_name, sc.backend);
  const Params fabric_bending = apply_fabric(mat, material_name);  // measured-fabric library (loom/fabric_library.hpp)
  const Params bending = mat.has("bending") ? mat.child("bending") : fabric_bending;  // hinge bending (loom/bending.hpp)
  sc.material = naming_key_owners(PluginKind::Material, material_name, mat, loader, [&] {
    return loader.registry().make_material(material_name, material_on_backend ? sc.backend : "cpu", mat, sc.mesh);
  });
  sc.material = add_bending(std::move(sc.material), with_section_spec(bending, "bending"), sc.mesh, sc.backend);
  return material_name;
}

void state(const Params& root, Scene& sc, const std::string& material_name) {
  const Params mat = root.child("material");
  State& st = sc.state;
  const Index n = sc.mesh.num_vertices();
  st.resize(n);
  st.x = sc.mesh.positions;
  sc.material->compute_masses(st.mass);
  for (Index i = 0; i < n; ++i)
    if (!(st.mass[i] > 0) || !std::isfinite(st.mass[i]))
      mat.fail("material '" + material_name + "' gave vertex " + std::to_string(i) + " the mass " + fmt(st.mass[i]) +
               "; masses must be finite and > 0. Fix: check density / vertex_mass, and that every vertex belongs to a triangle.");
  st.update_inverse_masses();

  // The keys below are declared in scene_section_spec (root carries it); their messages give
  // examples, so they are read here rather than through a ParamReader.
  // ---- initial shape: positions scaled about the centroid (rest shape unchanged) ----
  Params iscale = root.child("initial_scale");
  if (iscale.valid()) {
    const double f = iscale.as_double();
    if (!(f > 0) || !std::isfinite(f)) iscale.fail("must be a finite number > 0 (e.g. 0.5 starts the cloth compressed).");
    double c[3] = {0, 0, 0};
    for (Index i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) c[k] += st.x[3 * i + k] / n;
    for (Index i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) st.x[3 * i + k] = c[k] + f * (st.x[3 * i + k] - c[k]);
  }

  // ---- initial velocity ----
  Params v0 = root.child("initial_velocity");
  if (v0.valid()) {
    const auto v = finite3(v0, "", "e.g. [0, -5, 0] (m/s)");
    for (Index i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) st.v[3 * i + k] = v[k];
  }

  // ---- gravity ----
  Params grav = root.child("gravity");
  if (grav.valid()) {
    const auto g = finite3(grav, "gravity ", "e.g. [0, -9.81, 0]");
    sc.gravity = {g[0], g[1], g[2]};
  }
}

void selections(const Params& root, Scene& sc) {
  State& st = sc.state;
  // Optional per-vertex mass factors (hard cases: heavy vertices against a light cloth).
  Params mscale = root.child("mass_scale");
  if (mscale.valid()) {
    if (!mscale.is_sequence()) mscale.fail("must be a list like [{vertices: [0, 5], factor: 1.0e6}].");
    for (std::size_t k = 0; k < mscale.size(); ++k) {
      const Params e = with_section_spec(mscale.at(k), "mass_scale");
      if (!e.is_map()) e.fail("an entry is {vertices: [...], factor: f}, {group: name, factor: f} or {box: {min: [..], max: [..]}, factor: f}.");
      const double factor = ParamReader(e, mass_scale_entry_spec()).number("factor");
      const std::vector<Index> vs = select_vertices(sc.mesh, e);
      e.check_unused();
      for (Index i : vs) {
        st.mass[i] *= factor;
        if (!std::isfinite(st.mass[i]))
          e.child("factor").fail("makes the mass of vertex " + std::to_string(i) + " overflow to " + fmt(st.mass[i]) +
                                 " (factors of entries that select it multiply). Fix: use a smaller factor.");
      }
    }
  }
  st.update_inverse_masses();

  // pins (framework/src/pins.cpp: groups, regions, prescribed motion)
  sc.pins = PinSet::parse(root.child("pins"), sc.mesh, st);
}

void colliders(const Params& root, Scene& sc, const std::string& base_dir) {
  const State& st = sc.state;
  const Index n = st.size();
  sc.colliders = ColliderSet::parse(root.child("colliders"), base_dir);
  {
    // A contact offset larger than the whole cloth is a unit slip (it would throw the cloth
    // that far on the first contact): refuse it, naming the collider.
    double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    for (Index i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], st.x[3 * i + k]);
        hi[k] = std::max(hi[k], st.x[3 * i + k]);
      }
    const double size = std::sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                                  (hi[2] - lo[2]) * (hi[2] - lo[2]));
    const Params list = root.child("colliders");
    for (std::size_t c = 0; c < sc.colliders.size(); ++c)
      if (sc.colliders.colliders()[c].thickness > size)
        with_section_spec(list.at(c), "colliders").child("thickness").fail("the contact offset " + fmt(sc.colliders.colliders()[c].thickness) +
                                           " m is larger than the whole cloth (" + fmt(size) +
                                           " m across). Fix: give the thickness in metres (a few millimetres is usual).");
  }
  sc.self_collision = SelfCollision::parse(with_section_spec(root.child("self_collision"), "self_collision"), sc.mesh, st.x);
}

IntegratorChoice integrator(const Params& root, Scene& sc, PluginLoader& loader, const std::string& material_name) {
  IntegratorChoice c;
  const Params integ = with_section_spec(root.child("integrator"), "integrator");  // type, dt, substeps, frame_time (+ the plugin's)
  if (!integ.is_map()) root.fail("missing 'integrator' section. Fix: add integrator: {type: symplectic_euler, dt: 0.001, substeps: 10}.");
  const ParamReader integ_keys(integ, integrator_section_spec());  // the framework's keys (param_spec.cpp)
  c.name = integ_keys.text("type");
  c.dt = integ_keys.number("dt");
  std::int64_t substeps = integ.get("substeps", static_cast<std::int64_t>(1));
  if (integ.has("frame_time")) {
    // The frame time fixes the output rate; substeps follow dt (so --set integrator.dt=...
    // keeps the frames' spacing).
    if (integ.has("substeps"))
      integ.child("substeps").fail("give either frame_time or substeps, not both (frame_time sets substeps = frame_time / dt).");
    const double ft = integ_keys.number("frame_time");
    const double ratio = ft / c.dt;
    substeps = std::llround(ratio);
    if (substeps < 1 || std::abs(ratio - static_cast<double>(substeps)) > 1e-6 * ratio)
      integ.child("frame_time").fail("frame_time " + fmt(ft) + " s is not a whole number of steps of dt = " + fmt(c.dt) +
                                     " s (ratio " + fmt(ratio) + "). Fix: choose dt that divides frame_time.");
  }
  if (substeps < 1 || substeps > 100000000)
    integ.child("substeps").fail("must be an integer >= 1 and <= 1e8 (steps per frame).");
  c.substeps = static_cast<int>(substeps);
  try {
    loader.ensure(PluginKind::Integrator, c.name);
  } catch (const InputError& e) {
    integ.child("type").fail(e.what());
  }
  c.integrator = naming_key_owners(PluginKind::Integrator, c.name, integ, loader,
                                   [&] { return loader.registry().make_integrator(c.name, sc.backend, integ); });
  const IntegratorNeeds needs = c.integrator->needs();
  if (needs.springs && !sc.material->springs())
    integ.fail("integrator '" + c.name + "' works per spring, but material '" + material_name +
               "' has no springs. Fix: use material type mass_spring, or an integrator that works with any material "
               "(symplectic_euler, rk4, baraff_witkin).");
  if (needs.jacobian && !sc.material->has_jacobian())
    integ.fail("integrator '" + c.name + "' needs force Jacobians, which material '" + material_name +
               "' does not provide. Fix: use an explicit integrator (symplectic_euler, rk4) with this material.");
  return c;
}

namespace {

// The blocks of the solvers in `solver:` that this run does not use (a fallback of the type list
// on a build that has the first choice, or a block kept for --set solver.type=...), checked
// against their solver's declared keys as if it ran: a typo or a value out of range there is an
// error now, with its line, not on the machine that falls back to it. A solver whose module is
// not in this build (or does not load) cannot be checked and is left to that machine.
void check_other_solver_blocks(const Params& solver, const std::string& chosen, const std::string& backend,
                               PluginLoader& loader) {
  for (const auto& k : solver.keys()) {
    if (k == "type" || k == chosen || !loader.available(PluginKind::Solver, k)) continue;
    const Params block = solver.child(k);
    if (!block.valid()) continue;  // `name: null` removes a block
    try {
      loader.ensure(PluginKind::Solver, k);
    } catch (const InputError&) {
      continue;
    }
    const std::string be = loader.registry().has(PluginKind::Solver, k, backend) ? backend : "cpu";
    if (!loader.registry().has(PluginKind::Solver, k, be)) continue;
    if (const ParamSpec* spec = loader.registry().params(PluginKind::Solver, k, be)) check_params(block.with_spec(spec), *spec);
  }
}

}  // namespace

std::string solver(const Params& root, Scene& sc, PluginLoader& loader, const IntegratorNeeds& needs,
                   const std::string& integrator_name, bool notes) {
  if (needs.linear_solver) {
    // The section's keys: type (section_specs.cpp) and one block per solver of this build.
    ParamSpec spec = solver_section_spec();
    for (const auto& nm : loader.names(PluginKind::Solver))
      if (!spec.find(nm)) spec.open_map(nm).framework().help("keys of solver " + nm + ": loom plugins --params " + nm);
    const Params solver = root.child("solver").with_spec(&spec);
    if (!solver.valid())
      root.fail("integrator '" + integrator_name + "' is implicit and needs a linear solver. Fix: add "
                "solver: {type: eigen_pcg} (or a list: solver: {type: [cholmod, eigen_ldlt]}).");
    std::vector<std::string> names;
    Params type = solver.is_map() ? solver.child("type") : solver;
    if (type.is_scalar()) names.push_back(type.as_string());
    else if (type.is_sequence())
      for (std::size_t k = 0; k < type.size(); ++k) names.push_back(type.at(k).as_string());
    else
      (solver.is_map() ? solver : root).fail("solver needs 'type': a solver name or a list of names (first available is used).");
    if (names.empty()) type.fail("the solver list is empty.");
    for (const auto& nm : names)  // a listed solver this build lacks may have its block too
      if (!spec.find(nm)) spec.open_map(nm).framework();
    std::string chosen;
    std::vector<std::string> skipped;
    for (const auto& nm : names) {
      // the first available for this backend (a cpu-only solver is skipped on cuda)
      if (loader.available(PluginKind::Solver, nm) &&
          (sc.backend == "cpu" || loader.registry().has(PluginKind::Solver, nm, sc.backend))) { chosen = nm; break; }
      skipped.push_back(nm);
    }
    if (chosen.empty() && sc.backend != "cpu")  // none runs on this backend: the first one, whose make names the fix
      for (const auto& nm : names)
        if (loader.available(PluginKind::Solver, nm)) {
          chosen = nm;
          skipped.clear();
          break;
        }
    if (chosen.empty()) {
      const auto avail = loader.names(PluginKind::Solver);
      const std::string hint = names.size() == 1 ? closest_match(names[0], avail) : "";
      type.fail("none of the solvers [" + join(names) + "] is available in this build" +
                (hint.empty() ? "" : " (did you mean '" + hint + "'?)") + ". Available: " +
                (avail.empty() ? "none" : join(avail)) + ".");
    }
    if (!skipped.empty() && is_output_rank() && notes)
      std::cerr << "loom: solver " << join(skipped) << " not available in this build"
                << (sc.backend == "cpu" ? "" : " for backend " + sc.backend) << "; using " << chosen << "\n";
    loader.ensure(PluginKind::Solver, chosen);
    Params sp = solver.is_map() ? solver.child(chosen) : Params();
    if (solver.is_map()) {
      // Parameter blocks of other solvers may stay in the file (so that --set solver.type=...
      // can switch between them); a block for a name that is no solver at all is an error.
      for (const auto& nm : names) solver.mark_used(nm);
      for (const auto& k : solver.keys())
        if (k != "type" && loader.available(PluginKind::Solver, k)) solver.mark_used(k);
      solver.check_unused(loader.names(PluginKind::Solver));
    }
    sc.solver = loader.registry().make_solver(chosen, sc.backend, sp);
    if (solver.is_map()) check_other_solver_blocks(solver, chosen, sc.backend, loader);
    return chosen;
  } else if (const Params solver = root.child("solver"); solver.valid()) {  // ignored: its keys are not read
    if (solver.is_map())
      for (const auto& k : solver.keys()) solver.mark_used(k);
    if (is_output_rank() && notes)
      std::cerr << "loom: note: the 'solver' section is ignored: integrator '" << integrator_name
                << "' is explicit and solves no linear system.\n";
  }
  return "";
}

void output_and_guards(const Params& root, int& frames, OutputOptions& output_options, GuardOptions& guard_options) {
  frames = ParamReader(root, scene_section_spec()).int32("frames");
  if (const Params out = optional_section(root, "output", "{dir: out/run, obj: true, stats: true}"); out.valid()) {
    output_section_fields().read(out, output_options);  // every key, defaults OutputOptions's
    if (output_options.velocities && !output_options.vtk && !output_options.pc2)
      out.child("velocities").fail("velocities are written into the ParaView frames (vtk: true) and/or velocity.pc2 "
                                   "beside run.pc2 (pc2: true). Fix: turn one of them on.");
    out.check_unused();
  }
  if (const Params guard = optional_section(root, "guard", "{max_velocity: 1000, max_strain: 10}"); guard.valid()) {
    guard_section_fields().read(guard, guard_options);  // every key, defaults GuardOptions's
    guard.check_unused();
  }
}

}  // namespace loom::scene_build
