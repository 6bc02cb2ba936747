#include "loom/simulation.hpp"
#include "loom/memory_estimate.hpp"
#include "loom/bending.hpp"
#include "loom/fabric_library.hpp"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>

#include "loom/output.hpp"
#include "loom/pins.hpp"
#include "loom/restart.hpp"
#include "loom/run_output.hpp"
#include "loom/vtk_output.hpp"
#include "loom/threads.hpp"

namespace fs = std::filesystem;

namespace loom {

std::string resolve_path(const std::string& base_dir, const std::string& path) {
  if (path.empty() || fs::path(path).is_absolute() || base_dir.empty()) return path;
  return (fs::path(base_dir) / path).lexically_normal().string();
}

namespace {

std::string fmt(double v) {
  std::ostringstream os;
  os.precision(6);
  os << v;
  return os.str();
}

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : ", ") + x;
  return s;
}

}  // namespace

namespace {
bool g_notes = true;

// `threads: auto` (default) or a count; the policy lives in loom/threads.hpp.
void configure_threads(const Params& t, Scene& sc) {
  int requested = 0;
  if (t.valid()) {
    if (t.is_scalar() && t.as_string() == "auto") {
      requested = 0;
    } else {
      const std::int64_t k = t.as_int();
      if (k < 0 || k > kMaxThreads)
        t.fail("must be 'auto' or a count in [0, " + std::to_string(kMaxThreads) + "] (0 = auto); got " +
               std::to_string(k) + ". Fix: threads: auto uses the cores this process may run on.");
      requested = static_cast<int>(k);
    }
  }
  bool capped = false;
  sc.threads = resolve_thread_count(requested, &capped);
  if (capped && g_notes && is_output_rank())
    std::cerr << "loom: note: threads: " << requested << " capped at " << sc.threads
              << ", the cores this process may use (more threads than cores only wait at barriers).\n";
  omp_set_num_threads(sc.threads);
}
}
void Simulation::set_notes(bool on) { g_notes = on; }

Simulation::Simulation() = default;
Simulation::~Simulation() = default;

Simulation::Simulation(const std::string& path, const std::vector<std::string>& overrides, PluginLoader& loader) {
  std::error_code ec;
  if (!fs::exists(path, ec) && !ec) throw InputError(path + ": scene file not found. Fix: check the path (scenes/ has examples).");
  Params root = Params::from_file(path);
  for (const auto& o : overrides) {
    const auto eq = o.find('=');
    if (eq == std::string::npos || eq == 0)
      throw InputError("--set " + o + ": expected key=value, e.g. --set integrator.dt=0.0005");
    root.set_path(o.substr(0, eq), o.substr(eq + 1));
  }
  build(root, fs::path(path).parent_path().string(), loader);
}

std::unique_ptr<Simulation> Simulation::from_string(const std::string& yaml, const std::string& source_name,
                                                    const std::string& base_dir,
                                                    const std::vector<std::string>& overrides, PluginLoader& loader) {
  std::unique_ptr<Simulation> sim(new Simulation());
  Params root = Params::from_string(yaml, source_name);
  for (const auto& o : overrides) {
    const auto eq = o.find('=');
    if (eq == std::string::npos || eq == 0)
      throw InputError("--set " + o + ": expected key=value, e.g. --set integrator.dt=0.0005");
    root.set_path(o.substr(0, eq), o.substr(eq + 1));
  }
  sim->build(root, base_dir, loader);
  return sim;
}

// The estimate of the run's peak memory against the machine's (loom/memory_estimate.hpp),
// from the vertex count and the combo the scene names; the sections themselves are parsed later.
void Simulation::check_memory(const Params& root, long long vertices) {
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
  memory_line_ = "memory:     about " + format_bytes(est.bytes) + " at the peak (" + est.basis + ", " +
                 std::to_string(vertices) + " vertices)" +
                 (machine ? "; this machine has " + format_bytes(*machine) : std::string("; machine memory unknown"));
  if (machine && est.bytes > *machine)
    root.child("mesh").fail("this run needs about " + format_bytes(est.bytes) + " of memory (" + est.basis + ", " +
                            std::to_string(vertices) + " vertices), more than this machine's " +
                            format_bytes(*machine) + ". Fix: use a coarser mesh (fewer vertices), an iterative "
                            "solver instead of a direct one, or a machine with more memory.");
}

void Simulation::build(const Params& root, const std::string& base_dir, PluginLoader& loader) {
  if (!root.is_map()) root.fail("a scene file must be a YAML mapping with mesh, material, integrator, ... sections.");
  scene_ = std::make_unique<Scene>();
  Scene& sc = *scene_;
  sc.source = root.source();
  root.child("description");  // free text, allowed
  root.child("name");
  root.child("render");       // read by `loom render`, not by a run
  root.child("kawabata");     // read by scripts/kawabata.py (virtual KES-F tests), not by a run
  resolved_yaml_ = root.dump();
  base_dir_ = base_dir.empty() ? std::string(".") : base_dir;

  sc.backend = root.get_choice("backend", "cpu", {"cpu", "cuda"});
  configure_threads(root.child("threads"), sc);

  // ---- mesh ----
  Params mesh = root.child("mesh");
  if (!mesh.valid()) root.fail("missing 'mesh' section. Fix: add mesh: {grid: {nx: 32, ny: 32, width: 1, height: 1}} or mesh: {obj: file.obj}.");
  if (!mesh.is_map()) mesh.fail("must be a mapping with 'grid' or 'obj'.");
  const bool has_grid = mesh.has("grid"), has_obj = mesh.has("obj");
  if (has_grid == has_obj) mesh.fail("give exactly one of 'grid' or 'obj'.");
  if (has_grid) {
    Params g = mesh.child("grid");
    if (!g.is_map()) g.fail("must be a mapping like {nx: 32, ny: 32, width: 1.0, height: 1.0}.");
    const auto nx = g.require_int("nx"), ny = g.require_int("ny");
    if (nx < 2 || ny < 2 || nx > 20000 || ny > 20000) g.fail("nx and ny must be in [2, 20000] (got " + std::to_string(nx) + " x " + std::to_string(ny) + ").");
    const double w = g.get_positive("width", 1.0), h = g.get_positive("height", 1.0);
    const std::string plane = g.get_choice("plane", "xy", {"xy", "xz"});
    const std::string diag = g.get_choice("diagonals", "alternate", {"alternate", "uniform"});
    g.check_unused();
    check_memory(root, static_cast<long long>(nx) * ny);  // before the grid allocates anything
    sc.mesh = make_grid(static_cast<Index>(nx), static_cast<Index>(ny), w, h,
                        plane == "xy" ? GridPlane::XY : GridPlane::XZ, diag == "alternate");
  } else {
    Params o = mesh.child("obj");
    const std::string file = resolve_path(base_dir, o.as_string());
    if (!fs::exists(file)) o.fail("OBJ file '" + file + "' not found. Fix: paths are relative to the scene file's folder.");
    sc.mesh = read_obj(file);
    check_memory(root, static_cast<long long>(sc.mesh.num_vertices()));
    const double scale = mesh.get_positive("scale", 1.0);
    for (double& c : sc.mesh.positions) c *= scale;
  }
  mesh.check_unused();

  // ---- material ----
  Params mat = root.child("material");
  if (!mat.is_map()) root.fail("missing 'material' section. Fix: add material: {type: mass_spring, ...}.");
  material_name_ = mat.require_string("type");
  try {
    loader.ensure(PluginKind::Material, material_name_);
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
  const bool material_on_backend = loader.registry().has(PluginKind::Material, material_name_, sc.backend);
  const Params fabric_bending = apply_fabric(mat, material_name_);  // measured-fabric library (loom/fabric_library.hpp)
  const Params bending = mat.has("bending") ? mat.child("bending") : fabric_bending;  // hinge bending (loom/bending.hpp)
  sc.material = loader.registry().make_material(material_name_, material_on_backend ? sc.backend : "cpu", mat, sc.mesh);
  sc.material = add_bending(std::move(sc.material), bending, sc.mesh, sc.backend);

  // ---- state ----
  State& st = sc.state;
  const Index n = sc.mesh.num_vertices();
  st.resize(n);
  st.x = sc.mesh.positions;
  sc.material->compute_masses(st.mass);
  for (Index i = 0; i < n; ++i)
    if (!(st.mass[i] > 0) || !std::isfinite(st.mass[i]))
      mat.fail("material '" + material_name_ + "' gave vertex " + std::to_string(i) + " the mass " + fmt(st.mass[i]) +
               "; masses must be finite and > 0. Fix: check density / vertex_mass, and that every vertex belongs to a triangle.");
  // Optional per-vertex mass factors (hard cases: heavy vertices against a light cloth).
  Params mscale = root.child("mass_scale");
  if (mscale.valid()) {
    if (!mscale.is_sequence()) mscale.fail("must be a list like [{vertices: [0, 5], factor: 1.0e6}].");
    for (std::size_t k = 0; k < mscale.size(); ++k) {
      Params e = mscale.at(k);
      if (!e.is_map()) e.fail("an entry is {vertices: [...], factor: f}, {group: name, factor: f} or {box: {min: [..], max: [..]}, factor: f}.");
      const double factor = e.get_positive("factor", 1.0);
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
    const auto v = v0.as_doubles();
    if (v.size() != 3) v0.fail("needs 3 components, e.g. [0, -5, 0] (m/s).");
    for (double c : v)
      if (!std::isfinite(c)) v0.fail("components must be finite numbers.");
    for (Index i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) st.v[3 * i + k] = v[k];
  }

  // ---- pins (framework/src/pins.cpp: groups, regions, prescribed motion) ----
  sc.pins = PinSet::parse(root.child("pins"), sc.mesh, st);

  // ---- gravity ----
  Params grav = root.child("gravity");
  if (grav.valid()) {
    const auto g = grav.as_doubles();
    if (g.size() != 3) grav.fail("gravity needs 3 components, e.g. [0, -9.81, 0].");
    for (double c : g)
      if (!std::isfinite(c)) grav.fail("gravity components must be finite numbers.");
    sc.gravity = {g[0], g[1], g[2]};
  }

  // ---- colliders (only when declared) ----
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
        list.at(c).child("thickness").fail("the contact offset " + fmt(sc.colliders.colliders()[c].thickness) +
                                           " m is larger than the whole cloth (" + fmt(size) +
                                           " m across). Fix: give the thickness in metres (a few millimetres is usual).");
  }
  sc.self_collision = SelfCollision::parse(root.child("self_collision"), sc.mesh, st.x);

  // ---- integrator ----
  Params integ = root.child("integrator");
  if (!integ.is_map()) root.fail("missing 'integrator' section. Fix: add integrator: {type: symplectic_euler, dt: 0.001, substeps: 10}.");
  const ParamReader integ_keys(integ, integrator_section_spec());  // the framework's keys (param_spec.cpp)
  integrator_name_ = integ_keys.text("type");
  dt_ = integ_keys.number("dt");
  std::int64_t substeps = integ.get("substeps", static_cast<std::int64_t>(1));
  if (integ.has("frame_time")) {
    // The frame time fixes the output rate; substeps follow dt (so --set integrator.dt=...
    // keeps the frames' spacing).
    if (integ.has("substeps"))
      integ.child("substeps").fail("give either frame_time or substeps, not both (frame_time sets substeps = frame_time / dt).");
    const double ft = integ_keys.number("frame_time");
    const double ratio = ft / dt_;
    substeps = std::llround(ratio);
    if (substeps < 1 || std::abs(ratio - static_cast<double>(substeps)) > 1e-6 * ratio)
      integ.child("frame_time").fail("frame_time " + fmt(ft) + " s is not a whole number of steps of dt = " + fmt(dt_) +
                                     " s (ratio " + fmt(ratio) + "). Fix: choose dt that divides frame_time.");
  }
  if (substeps < 1 || substeps > 100000000)
    integ.child("substeps").fail("must be an integer >= 1 and <= 1e8 (steps per frame).");
  substeps_ = static_cast<int>(substeps);
  try {
    loader.ensure(PluginKind::Integrator, integrator_name_);
  } catch (const InputError& e) {
    integ.child("type").fail(e.what());
  }
  integrator_ = loader.registry().make_integrator(integrator_name_, sc.backend, integ);
  const IntegratorNeeds needs = integrator_->needs();
  if (needs.springs && !sc.material->springs())
    integ.fail("integrator '" + integrator_name_ + "' works per spring, but material '" + material_name_ +
               "' has no springs. Fix: use material type mass_spring, or an integrator that works with any material "
               "(symplectic_euler, rk4, baraff_witkin).");
  if (needs.jacobian && !sc.material->has_jacobian())
    integ.fail("integrator '" + integrator_name_ + "' needs force Jacobians, which material '" + material_name_ +
               "' does not provide. Fix: use an explicit integrator (symplectic_euler, rk4) with this material.");

  // ---- solver ----
  Params solver = root.child("solver");
  if (needs.linear_solver) {
    if (!solver.valid())
      root.fail("integrator '" + integrator_name_ + "' is implicit and needs a linear solver. Fix: add "
                "solver: {type: eigen_pcg} (or a list: solver: {type: [cholmod, eigen_ldlt]}).");
    std::vector<std::string> names;
    Params type = solver.is_map() ? solver.child("type") : solver;
    if (type.is_scalar()) names.push_back(type.as_string());
    else if (type.is_sequence())
      for (std::size_t k = 0; k < type.size(); ++k) names.push_back(type.at(k).as_string());
    else
      (solver.is_map() ? solver : root).fail("solver needs 'type': a solver name or a list of names (first available is used).");
    if (names.empty()) type.fail("the solver list is empty.");
    std::string chosen;
    std::vector<std::string> skipped;
    for (const auto& nm : names) {
      if (loader.available(PluginKind::Solver, nm)) { chosen = nm; break; }
      skipped.push_back(nm);
    }
    if (chosen.empty()) {
      const auto avail = loader.names(PluginKind::Solver);
      const std::string hint = names.size() == 1 ? closest_match(names[0], avail) : "";
      type.fail("none of the solvers [" + join(names) + "] is available in this build" +
                (hint.empty() ? "" : " (did you mean '" + hint + "'?)") + ". Available: " +
                (avail.empty() ? "none" : join(avail)) + ".");
    }
    if (!skipped.empty() && is_output_rank() && g_notes)
      std::cerr << "loom: solver " << join(skipped) << " not available in this build; using " << chosen << "\n";
    solver_name_ = chosen;
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
  } else if (solver.valid()) {
    if (solver.is_map())
      for (const auto& k : solver.keys()) solver.mark_used(k);
    solver_name_ = "";
    if (is_output_rank() && g_notes)
      std::cerr << "loom: note: the 'solver' section is ignored: integrator '" << integrator_name_
                << "' is explicit and solves no linear system.\n";
  }

  // ---- frames, output, guards ----
  frames_ = root.get("frames", 60);
  if (frames_ < 0) root.child("frames").fail("must be >= 0.");
  Params out = root.child("output");
  if (out.valid()) {
    if (!out.is_map()) out.fail("must be a mapping like {dir: out/run, obj: true, stats: true}.");
    output_.dir = out.get("dir", std::string());
    output_.obj = out.get("obj", true);
    output_.stats = out.get("stats", true);
    output_.every = out.get("every", 1);
    if (output_.every < 1) out.child("every").fail("must be >= 1 (write every n-th frame).");
    output_.pc2 = out.get("pc2", false);
    output_.uvs = out.get("uvs", false);
    output_.normals = out.get("normals", false);
    output_.lossless = out.get("lossless", false);
    output_.vtk = out.get("vtk", false);
    output_.velocities = out.get("velocities", false);
    output_.restart = out.get("restart", true);
    if (output_.velocities && !output_.vtk && !output_.pc2)
      out.child("velocities").fail("velocities are written into the ParaView frames (vtk: true) and/or velocity.pc2 "
                                   "beside run.pc2 (pc2: true). Fix: turn one of them on.");
    out.check_unused();
  }
  Params guard = root.child("guard");
  if (guard.valid()) {
    if (!guard.is_map()) guard.fail("must be a mapping like {max_velocity: 1000, max_strain: 10}.");
    guard_.max_velocity = guard.get_positive("max_velocity", guard_.max_velocity);
    guard_.max_strain = guard.get_positive("max_strain", guard_.max_strain);
    guard_.check_every = guard.get("check_every", 1);
    if (guard_.check_every < 1) guard.child("check_every").fail("must be >= 1.");
    guard.check_unused();
  }
  root.check_unused();

  integrator_->prepare(sc, dt_);
  prepared_ = true;
}

std::vector<std::string> Simulation::describe() const {
  const Scene& sc = *scene_;
  std::vector<std::string> lines;
  lines.push_back("scene:      " + sc.source);
  lines.push_back("mesh:       " + sc.mesh.source + " (" + std::to_string(sc.mesh.num_vertices()) + " vertices, " +
                  std::to_string(sc.mesh.num_triangles()) + " triangles)");
  std::string m = "material:   " + material_name_;
  for (const auto& [k, v] : sc.material->describe()) m += ", " + k + " " + v;
  lines.push_back(m);
  lines.push_back("integrator: " + integrator_name_ + ", dt " + fmt(dt_) + " s, " + std::to_string(substeps_) +
                  " steps per frame (frame time " + fmt(dt_ * static_cast<double>(substeps_)) + " s)");
  if (!solver_name_.empty()) lines.push_back("solver:     " + solver_name_);
  lines.push_back("backend:    " + sc.backend + ", threads " + std::to_string(sc.threads) + " (of " +
                  std::to_string(usable_cores()) + " usable cores)");
  double mass = 0;
  for (double mi : sc.state.mass) mass += mi;
  std::string pl = "pins:       " + std::to_string(sc.state.pin_list.size()) + " vertices";
  for (const PinGroup& g : sc.pins.groups())
    pl += (&g == &sc.pins.groups().front() ? " (" : ", ") + g.name + ": " + std::to_string(g.vertices.size()) +
          (g.moving() ? " moving" : " fixed") + (&g == &sc.pins.groups().back() ? ")" : "");
  lines.push_back(pl + "; total mass " + fmt(mass) + " kg");
  if (!sc.colliders.empty()) {
    std::string c = "colliders:  ";
    for (std::size_t k = 0; k < sc.colliders.size(); ++k) c += (k ? ", " : "") + sc.colliders.colliders()[k].name;
    lines.push_back(c);
  }
  if (sc.self_collision)
    lines.push_back("self-collision: thickness " + fmt(sc.self_collision->options().thickness) + " m, friction " +
                    fmt(sc.self_collision->options().friction));
  lines.push_back("gravity:    [" + fmt(sc.gravity[0]) + ", " + fmt(sc.gravity[1]) + ", " + fmt(sc.gravity[2]) + "]");
  lines.push_back("frames:     " + std::to_string(frames_) + " (" + fmt(static_cast<double>(frames_) * substeps_ * dt_) + " s simulated)");
  if (!memory_line_.empty()) lines.push_back(memory_line_);
  lines.push_back("output:     " + (output_.dir.empty() ? std::string("none") : output_.dir));
  return lines;
}

void Simulation::check_state(bool check_strain) {
  const State& st = scene_->state;
  const Index n = st.size();
  const double vmax2 = guard_.max_velocity * guard_.max_velocity;
  Index bad = std::numeric_limits<Index>::max();
  const double* x = st.x.data();
  const double* v = st.v.data();
#pragma omp parallel for reduction(min : bad) schedule(static) if (n >= kParallelMinVertices)
  for (Index i = 0; i < n; ++i) {
    const double a = x[3 * i] + x[3 * i + 1] + x[3 * i + 2];
    const double v2 = v[3 * i] * v[3 * i] + v[3 * i + 1] * v[3 * i + 1] + v[3 * i + 2] * v[3 * i + 2];
    // NaN fails every comparison: !(v2 <= vmax2) catches NaN and Inf too.
    if (!(v2 <= vmax2) || !std::isfinite(a)) bad = std::min(bad, i);
  }
  const std::string when = "step " + std::to_string(st.step) + " (t = " + fmt(st.time) + " s)";
  const std::string fix = " Fix: reduce integrator.dt (or raise substeps), add damping, or choose a more stable "
                          "integrator (baraff_witkin); raise guard.max_velocity only if such speeds are real.";
  if (bad != std::numeric_limits<Index>::max()) {
    const double* xi = &x[3 * bad];
    const double* vi = &v[3 * bad];
    const double speed = std::sqrt(vi[0] * vi[0] + vi[1] * vi[1] + vi[2] * vi[2]);
    std::string what;
    if (!std::isfinite(xi[0]) || !std::isfinite(xi[1]) || !std::isfinite(xi[2]))
      what = "position (" + fmt(xi[0]) + ", " + fmt(xi[1]) + ", " + fmt(xi[2]) + ") is not finite";
    else if (!std::isfinite(speed))
      what = "velocity (" + fmt(vi[0]) + ", " + fmt(vi[1]) + ", " + fmt(vi[2]) + ") is not finite";
    else
      what = "speed " + fmt(speed) + " m/s exceeds guard.max_velocity = " + fmt(guard_.max_velocity) + " m/s";
    throw DivergenceError("diverged at " + when + ": vertex " + std::to_string(bad) + ": " + what + "." + fix);
  }
  if (check_strain) {
    const double s = scene_->material->max_strain(st.x);
    if (!(s <= guard_.max_strain))
      throw DivergenceError("diverged at " + when + ": the largest strain is " + fmt(s) + ", beyond guard.max_strain = " +
                            fmt(guard_.max_strain) + "." + fix);
  }
}

namespace {
volatile std::sig_atomic_t g_stop_requested = 0;
}
void Simulation::request_stop() { g_stop_requested = 1; }

void Simulation::step() {
  if (g_stop_requested)
    throw Interrupted("interrupted at step " + std::to_string(scene_->state.step) + " (t = " + fmt(scene_->state.time) + " s)");
  const auto t0 = std::chrono::steady_clock::now();
  if (scene_->self_collision) scene_->self_collision->begin_step(scene_->state);
  integrator_->step(*scene_, dt_);
  if (!scene_->colliders.empty() && !integrator_->handles_contacts())
    scene_->colliders.resolve_contacts(scene_->state, scene_->state.time, dt_);
  if (scene_->self_collision) scene_->self_collision->resolve(scene_->state, dt_);  // after colliders: last word
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  step_seconds_ += secs;
  step_seconds_total_ += secs;
  ++steps_in_frame_;
  const StepStats s = integrator_->last_step();
  force_evals_ += s.force_evaluations;
  linear_iters_ += s.linear_iterations;
  if (scene_->state.step % guard_.check_every == 0) check_state(false);
  if (on_step_) on_step_();
}

void Simulation::advance_frame() {
  for (int k = 0; k < substeps_; ++k) step();
  check_state(true);
}

Simulation::FrameStats Simulation::measure(int frame) const {
  const Scene& sc = *scene_;
  FrameStats fs;
  fs.frame = frame;
  fs.time = sc.state.time;
  fs.kinetic = kinetic_energy(sc.state);
  fs.gravitational = gravitational_energy(sc.state, sc.gravity.data());
  fs.elastic = sc.material->elastic_energy(sc.state.x);
  fs.max_strain = sc.material->max_strain(sc.state.x);
  fs.wall_ms_per_step = steps_in_frame_ > 0 ? 1e3 * step_seconds_ / steps_in_frame_ : 0.0;
  fs.force_evaluations = force_evals_;
  fs.linear_iterations = linear_iters_;
  return fs;
}

// A run never mixes its files with another run's: the files of an earlier run of the same
// scene (same resolved scene.yaml) are cleared first; another scene's are refused unless
// output.overwrite (loom run --overwrite) says to replace them.
void Simulation::claim_output_dir(const std::string& scene_text) const {
  const auto files = run_files_in(output_.dir);
  if (files.empty()) return;
  std::ifstream in(fs::path(output_.dir) / "scene.yaml", std::ios::binary);
  const std::string previous((std::istreambuf_iterator<char>(in)), {});
  if (!output_.overwrite && previous != scene_text)
    throw InputError("output folder '" + output_.dir + "' holds the files of another run (" +
                     std::to_string(files.size()) + " files, e.g. " + fs::path(files.front()).filename().string() +
                     (previous.empty() ? ", without its scene.yaml" : ", of a different scene or --set") +
                     "). Fix: loom run ... --overwrite replaces them, or choose another folder with --out DIR.");
  // stats.csv first: a run killed while clearing never leaves more stats rows than frames.
  auto rank = [](const std::string& f) {
    const std::string name = fs::path(f).filename().string();
    return name == "restart.bin" ? -1 : name == "stats.csv" ? 0 : name == "run.pc2" ? 1 : name == "scene.yaml" ? 2 : 3;
  };
  std::vector<std::string> order = files;
  std::stable_sort(order.begin(), order.end(), [&](const std::string& a, const std::string& b) { return rank(a) < rank(b); });
  for (const auto& f : order) {
    std::error_code ec;
    fs::remove(f, ec);
    if (ec) throw InputError("cannot remove " + f + " from the earlier run: " + ec.message() + ".");
  }
}

void Simulation::run(const std::function<void(int, int)>& progress) {
  // The initial state passes the same guards as every step before anything is written.
  try {
    check_state(true);
  } catch (const DivergenceError& e) {
    throw InputError(std::string("the initial state (initial_velocity, initial_scale, pins) is out of bounds, nothing was written: ") + e.what());
  }
  const bool write = !output_.dir.empty() && is_output_rank();
  const bool resuming = resume_frame_ >= 0;
  const int first_frame = start_frame();
  std::ofstream stats;
  std::streamoff stats_complete = 0;  // bytes of stats.csv that hold complete rows
  std::unique_ptr<OutputLock> lock;
  std::error_code ec;
  const std::string abs_base = fs::absolute(base_dir_, ec).lexically_normal().string();
  const std::string scene_text = "# The scene as it ran (overrides applied), written by loom run.\n"
                                 "# Relative paths resolve against the original scene's folder:\n"
                                 "# loom-scene-dir: " + abs_base + "\n" + scene_file_line() + resolved_yaml_ + "\n";
  std::vector<double> reaction_work, reactions;
  if (write) {
    prepare_output_dir(output_.dir);
    lock = std::make_unique<OutputLock>(output_.dir);
    remove_stale_temporaries(output_.dir);
    if (resuming) {
      // Under the lock: the restart point must still be the one resume() read.
      if (read_restart(output_.dir).frame != resume_frame_)
        throw InputError("output folder '" + output_.dir + "' changed while resuming. Fix: run --resume again.");
      trim_run_for_resume(output_.dir, resume_frame_, output_.stats);
    } else {
      claim_output_dir(scene_text);
    }
    // Record exactly what ran (with --set overrides applied).
    if (output_.stats && resuming) {
      const std::string path = (fs::path(output_.dir) / "stats.csv").string();
      stats_complete = static_cast<std::streamoff>(fs::file_size(path));  // trimmed to complete rows
      stats.open(path, std::ios::app);
      if (!stats) throw InputError("cannot write " + path + ". Fix: check the folder's permissions.");
      stats.precision(10);
    } else if (output_.stats) {
      stats.open((fs::path(output_.dir) / "stats.csv").string(), std::ios::trunc);
      if (!stats) throw InputError("cannot write " + output_.dir + "/stats.csv. Fix: choose a writable --out folder.");
      stats << "frame,time,kinetic_energy,gravitational_energy,elastic_energy,total_energy,max_strain,"
               "wall_ms_per_step,force_evaluations,linear_iterations"
            << scene_->pins.csv_header() << '\n';
      stats.precision(10);
      stats.flush();
      if (!stats) throw OutputError("cannot write " + output_.dir + "/stats.csv (" + std::strerror(errno) + "; disk full?)");
      stats_complete = stats.tellp();
    }
  }
  const ObjOptions obj_options{output_.uvs, output_.normals, output_.lossless};
  std::optional<PointCacheWriter> pc2, vel_pc2;
  const std::string pc2_path = (fs::path(output_.dir) / "run.pc2").string();
  const std::string vel_pc2_path = (fs::path(output_.dir) / "velocity.pc2").string();
  const int points = static_cast<int>(scene_->mesh.num_vertices());
  if (write && output_.pc2 && resuming) {
    const int keep = first_frame / output_.every + 1;  // the samples of frames 0, every, ... <= first_frame
    pc2.emplace(pc2_path, points, keep);
    if (output_.velocities) vel_pc2.emplace(vel_pc2_path, points, keep);
  } else if (write && output_.pc2) {
    // The rest pose (topology, UVs, normals) that the point cache animates.
    write_file_atomic((fs::path(output_.dir) / "rest.obj").string(),
                      obj_text(scene_->mesh, scene_->state.x, "rest pose for run.pc2", {true, true, output_.lossless}));
    // PC2's sample rate is the frame step between samples.
    pc2.emplace(pc2_path, points, 0.0f, static_cast<float>(output_.every));
    if (output_.velocities) vel_pc2.emplace(vel_pc2_path, points, 0.0f, static_cast<float>(output_.every));
  }
  std::optional<VtkSeriesWriter> vtk;
  std::vector<double> gap_work;  // per-vertex collider gap for the ParaView frames
  if (write && output_.vtk) {
    vtk.emplace(output_.dir, scene_->mesh);
    if (resuming) vtk->adopt_existing(first_frame);
  }
  auto emit = [&](int frame) {
    if (!write) return;
    const FrameStats f = measure(frame);
    // No output ever carries a non-finite number: energies that overflow (positions near the
    // double range, absurd masses) stop the run as diverged before this frame is written.
    for (double q : {f.kinetic, f.gravitational, f.elastic, f.kinetic + f.gravitational + f.elastic, f.max_strain})
      if (!std::isfinite(q))
        throw DivergenceError("diverged at frame " + std::to_string(frame) + " (t = " + fmt(f.time) +
                              " s): the energies are not finite (kinetic " + fmt(f.kinetic) + ", gravitational " +
                              fmt(f.gravitational) + ", elastic " + fmt(f.elastic) + ", strain " + fmt(f.max_strain) +
                              "). Fix: check masses, scales and collider offsets for values near the double range.");
    // Frame files first, then the stats row: a killed run never has a row for a frame it did
    // not write.
    if (frame % output_.every == 0) {
      if (output_.obj) {
        char name[32];
        std::snprintf(name, sizeof(name), "frame_%05d.obj", frame);
        write_file_atomic((fs::path(output_.dir) / name).string(),
                          obj_text(scene_->mesh, scene_->state.x, "t = " + fmt(scene_->state.time) + " s", obj_options));
      }
      if (vtk) {
        // Per vertex, the signed distance to the nearest collider's offset surface (contact field).
        const auto& cs = scene_->colliders.colliders();
        if (!cs.empty()) {
          const std::size_t n = scene_->state.x.size() / 3;
          gap_work.assign(n, std::numeric_limits<double>::infinity());
          for (const Collider& c : cs) {
            const Collider::Frame fr = c.frame_at(scene_->state.time);
            for (std::size_t i = 0; i < n; ++i)
              gap_work[i] = std::min(gap_work[i], c.query(fr, &scene_->state.x[3 * i]).distance);
          }
        }
        vtk->write_frame(frame, scene_->state.time, scene_->state.x,
                         output_.velocities ? std::span<const double>(scene_->state.v) : std::span<const double>(),
                         gap_work);
      }
      if (pc2) pc2->append(scene_->state.x);
      if (vel_pc2) vel_pc2->append(scene_->state.v);
    }
    if (output_.stats) {
      stats << f.frame << ',' << f.time << ',' << f.kinetic << ',' << f.gravitational << ',' << f.elastic << ','
            << (f.kinetic + f.gravitational + f.elastic) << ',' << f.max_strain << ',' << f.wall_ms_per_step << ','
            << f.force_evaluations << ',' << f.linear_iterations;
      if (!scene_->pins.empty()) {  // reaction force of each pin group on the cloth (N)
        scene_->pins.reactions(scene_->state, *scene_->material, scene_->gravity, reaction_work, reactions);
        for (double r : reactions) stats << ',' << r;
      }
      stats << '\n';
      stats.flush();
      if (!stats) {
        // Cut the partial row off (truncation frees space, so it works on a full disk too):
        // stats.csv keeps only complete rows, one per frame written.
        const std::string path = (fs::path(output_.dir) / "stats.csv").string();
        const std::string why = std::strerror(errno);
        stats.close();
        std::error_code trunc_ec;
        if (stats_complete > 0) fs::resize_file(path, static_cast<std::uintmax_t>(stats_complete), trunc_ec);
        throw OutputError("cannot write " + path + " (" + why + "; disk full?); the frames written so far are kept" +
                                 (trunc_ec ? std::string(", but the last row may be incomplete") : std::string()) + ".");
      }
      stats_complete = stats.tellp();
    }
    // Last: the restart point of this frame, once everything before it is on disk.
    if (output_.restart) {
      RestartData r;
      r.frame = frame;
      r.frames = frames_;
      r.step = scene_->state.step;
      r.time = scene_->state.time;
      r.force_evaluations = force_evals_;
      r.linear_iterations = linear_iters_;
      r.x = scene_->state.x;
      r.v = scene_->state.v;
      r.integrator_state = integrator_->restart_state();
      write_restart(output_.dir, r);
    }
  };
  if (write && !resuming) write_file_atomic((fs::path(output_.dir) / "scene.yaml").string(), scene_text);
  if (!resuming) emit(0);
  for (int f = first_frame + 1; f <= frames_; ++f) {
    step_seconds_ = 0;
    steps_in_frame_ = 0;
    advance_frame();
    emit(f);
    if (progress) progress(f, frames_);
  }
}

// "# loom-scene-file: PATH\n" (the scene file a run was made from, absolute) for scene.yaml:
// loom run --resume builds from the copy with that name, so that plugins resolving paths
// against their scene file (gnatv's material_file) find the same files.
std::string Simulation::scene_file_line() const {
  const std::string& src = scene_->source;
  if (src.empty() || src.front() == '<') return {};
  std::error_code ec;
  return "# loom-scene-file: " + fs::absolute(src, ec).lexically_normal().string() + "\n";
}

int Simulation::resume(int frames) {
  if (output_.dir.empty()) throw InputError("--resume needs the run's output folder.");
  const RestartData r = read_restart(output_.dir);
  frames_ = frames >= 0 ? frames : r.frames;
  State& st = scene_->state;
  const std::string where = output_.dir + "/restart.bin";
  if (r.x.size() != st.x.size())
    throw InputError(where + ": holds " + std::to_string(r.x.size() / 3) + " vertices, the scene has " +
                     std::to_string(st.x.size() / 3) + ". Fix: resume with the scene that made the run (its scene.yaml).");
  if (r.frame > frames_)
    throw InputError(where + ": the run is already at frame " + std::to_string(r.frame) + " of " + std::to_string(frames_) +
                     ". Fix: give --frames N with N > " + std::to_string(r.frame) + " to continue it further.");
  if (r.frame == frames_ && frames < 0)
    throw InputError(where + ": the run is complete (frame " + std::to_string(r.frame) + " of " + std::to_string(frames_) +
                     "): nothing to resume. Fix: give --frames N with N > " + std::to_string(r.frame) + " to continue it.");
  for (std::size_t i = 0; i < r.x.size(); ++i)
    if (!std::isfinite(r.x[i]) || !std::isfinite(r.v[i])) throw InputError(where + ": holds non-finite values. Fix: rerun with --overwrite.");
  st.x = r.x;
  st.v = r.v;
  st.time = r.time;
  st.step = r.step;
  force_evals_ = r.force_evaluations;
  linear_iters_ = r.linear_iterations;
  if (!integrator_->set_restart_state(r.integrator_state))
    throw InputError(where + ": its integrator state (" + std::to_string(r.integrator_state.size()) +
                     " numbers) does not fit integrator '" + integrator_name_ +
                     "'. Fix: resume with the scene that made the run, or rerun it with --overwrite.");
  resume_frame_ = r.frame;
  return r.frame;
}

}  // namespace loom
