#include "loom/pins.hpp"
#include "loom/section_specs.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "loom/material.hpp"
#include "loom/rotation.hpp"

namespace loom {

namespace {

std::string join_names(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : ", ") + x;
  return s;
}

std::string num(double v) {
  std::ostringstream os;
  os.precision(6);
  os << v;
  return os.str();
}

const std::vector<std::string> kPinGroups = {"top_corners", "top_edge", "left_corners", "left_edge",
                                             "bottom_corners", "bottom_edge", "right_edge", "corners"};

// Vertices of a named group. Grids use their structure; other meshes use the bounding box,
// with the grid's conventions for which side is which: "top" is the largest y and "left" the
// smallest x, except on a mesh lying flat (its extent along y below 1% of its largest
// extent), where "top" is the smallest z as on a `plane: xz` grid (rows run along -z), and on
// a mesh standing in the yz plane (x extent below 1%), where "left" is the smallest z.
std::vector<Index> named_group(const Mesh& mesh, const std::string& group, const Params& where) {
  std::vector<Index> out;
  const Index n = mesh.num_vertices();
  if (mesh.grid) {
    const GridInfo& g = *mesh.grid;
    auto row = [&](Index iy) { for (Index ix = 0; ix < g.nx; ++ix) out.push_back(g.index(ix, iy)); };
    auto colm = [&](Index ix) { for (Index iy = 0; iy < g.ny; ++iy) out.push_back(g.index(ix, iy)); };
    if (group == "top_corners") out = {g.index(0, g.ny - 1), g.index(g.nx - 1, g.ny - 1)};
    else if (group == "top_edge") row(g.ny - 1);
    else if (group == "bottom_edge") row(0);
    else if (group == "left_corners") out = {g.index(0, 0), g.index(0, g.ny - 1)};
    else if (group == "left_edge") colm(0);
    else if (group == "right_edge") colm(g.nx - 1);
    else if (group == "bottom_corners") out = {g.index(0, 0), g.index(g.nx - 1, 0)};
    else if (group == "corners") out = {g.index(0, 0), g.index(g.nx - 1, 0), g.index(0, g.ny - 1), g.index(g.nx - 1, g.ny - 1)};
  } else {
    double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    for (Index i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], mesh.positions[3 * i + k]);
        hi[k] = std::max(hi[k], mesh.positions[3 * i + k]);
      }
    const double ext = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
    const double tol = 1e-6 * ext;
    // The up axis and the sense of "top"; the left-right axis and the sense of "right".
    const bool flat_xz = hi[1] - lo[1] < 0.01 * ext;
    const bool flat_yz = !flat_xz && hi[0] - lo[0] < 0.01 * ext;
    const int up = flat_xz ? 2 : 1, across = flat_yz ? 2 : 0;
    const bool top_high = !flat_xz;  // flat in xz: top = smallest z
    // select(axis, high) with axis 1 = up, 0 = across in the mesh's own frame.
    auto select = [&](int which, bool high) {
      const int axis = which == 1 ? up : across;
      if (which == 1 && !top_high) high = !high;
      std::vector<Index> s;
      for (Index i = 0; i < n; ++i) {
        const double c = mesh.positions[3 * i + axis];
        if (high ? c >= hi[axis] - tol : c <= lo[axis] + tol) s.push_back(i);
      }
      return s;
    };
    auto extremes = [&](const std::vector<Index>& s, int which) {
      if (s.empty()) return std::vector<Index>{};
      const int axis = which == 1 ? up : across;
      Index a = s[0], b = s[0];
      for (Index i : s) {
        if (mesh.positions[3 * i + axis] < mesh.positions[3 * a + axis]) a = i;
        if (mesh.positions[3 * i + axis] > mesh.positions[3 * b + axis]) b = i;
      }
      return a == b ? std::vector<Index>{a} : std::vector<Index>{a, b};
    };
    if (group == "top_edge") out = select(1, true);
    else if (group == "bottom_edge") out = select(1, false);
    else if (group == "left_edge") out = select(0, false);
    else if (group == "right_edge") out = select(0, true);
    else if (group == "top_corners") out = extremes(select(1, true), 0);
    else if (group == "bottom_corners") out = extremes(select(1, false), 0);
    else if (group == "left_corners") out = extremes(select(0, false), 1);
    else if (group == "corners") {
      out = extremes(select(1, true), 0);
      auto b = extremes(select(1, false), 0);
      out.insert(out.end(), b.begin(), b.end());
    }
  }
  if (out.empty() && std::find(kPinGroups.begin(), kPinGroups.end(), group) == kPinGroups.end()) {
    const std::string hint = closest_match(group, kPinGroups);
    where.fail("unknown pin group '" + group + "'" + (hint.empty() ? "" : " (did you mean '" + hint + "'?)") +
               ". Groups: " + join_names(kPinGroups) + "; or give {vertices: [i, j, ...]} or {box: {min: [x, y, z], max: [x, y, z]}}.");
  }
  return out;
}

Vec3 read3(const Params& c, const char* what) {
  const auto v = c.as_doubles();
  if (v.size() != 3) c.fail(std::string(what) + " needs 3 numbers, e.g. [0, 0, 0].");
  for (double x : v)
    if (!std::isfinite(x)) c.fail(std::string(what) + " components must be finite numbers.");
  return {v[0], v[1], v[2]};
}

std::vector<Index> box_vertices(const Mesh& mesh, const Params& box) {
  if (!box.is_map()) box.fail("box is {min: [x, y, z], max: [x, y, z]} (metres, the mesh's rest coordinates).");
  Params pmin = box.child("min"), pmax = box.child("max");
  if (!pmin.valid() || !pmax.valid()) box.fail("box needs both 'min' and 'max', e.g. {min: [-1, 0.99, -1], max: [1, 1.01, 1]}.");
  const Vec3 lo = read3(pmin, "min"), hi = read3(pmax, "max");
  for (int k = 0; k < 3; ++k)
    if (lo[k] > hi[k]) box.fail("box min must not exceed max in any coordinate (coordinate " + std::to_string(k) + ": " + num(lo[k]) + " > " + num(hi[k]) + ").");
  box.check_unused();
  std::vector<Index> out;
  const Index n = mesh.num_vertices();
  double mlo[3] = {1e300, 1e300, 1e300}, mhi[3] = {-1e300, -1e300, -1e300};
  for (Index i = 0; i < n; ++i) {
    const double* x = &mesh.positions[3 * static_cast<std::size_t>(i)];
    bool in = true;
    for (int k = 0; k < 3; ++k) {
      in = in && x[k] >= lo[k] && x[k] <= hi[k];
      mlo[k] = std::min(mlo[k], x[k]);
      mhi[k] = std::max(mhi[k], x[k]);
    }
    if (in) out.push_back(i);
  }
  if (out.empty())
    box.fail("the box [" + num(lo[0]) + ", " + num(lo[1]) + ", " + num(lo[2]) + "] .. [" + num(hi[0]) + ", " +
             num(hi[1]) + ", " + num(hi[2]) + "] selects no vertex; the mesh spans [" + num(mlo[0]) + ", " +
             num(mlo[1]) + ", " + num(mlo[2]) + "] .. [" + num(mhi[0]) + ", " + num(mhi[1]) + ", " + num(mhi[2]) +
             "]. Fix: enlarge the box so that it contains the vertices to select (a flat mesh needs a box with "
             "some thickness around its plane).");
  return out;
}

Vec3 cross3(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// Placement of a group at one time: c(t), rotation matrix, linear and angular velocity and
// acceleration. Computed once per group per call, then applied per vertex.
struct Placement {
  Vec3 c, vlin, alin, omega, alpha;
  double R[9];
};

Placement placement(const PinGroup& g, double t) {
  Placement p;
  const RigidMotion& m = g.motion;
  const Vec3 d = m.displacement(t);
  for (int k = 0; k < 3; ++k) p.c[k] = g.center[k] + d[k];
  p.vlin = m.linear_velocity(t);
  p.alin = m.linear_acceleration(t);
  const double w = m.spin(t), dw = m.spin_acceleration(t);
  const Vec3& a = m.axis;
  for (int k = 0; k < 3; ++k) {
    p.omega[k] = w * a[k];
    p.alpha[k] = dw * a[k];
  }
  axis_angle_matrix(a.data(), m.angle(t), p.R);  // Rodrigues
  return p;
}

// Position (and velocity, acceleration when asked) of rest point X under a placement.
inline void place_point(const Placement& p, const Vec3& center, const double* X, double* x, double* v, double* acc) {
  const Vec3 r0{X[0] - center[0], X[1] - center[1], X[2] - center[2]};
  const Vec3 r{p.R[0] * r0[0] + p.R[1] * r0[1] + p.R[2] * r0[2], p.R[3] * r0[0] + p.R[4] * r0[1] + p.R[5] * r0[2],
               p.R[6] * r0[0] + p.R[7] * r0[1] + p.R[8] * r0[2]};
  for (int k = 0; k < 3; ++k) x[k] = p.c[k] + r[k];
  if (v) {
    const Vec3 wr = cross3(p.omega, r);
    for (int k = 0; k < 3; ++k) v[k] = p.vlin[k] + wr[k];
  }
  if (acc) {
    const Vec3 ar = cross3(p.alpha, r);
    const Vec3 wwr = cross3(p.omega, cross3(p.omega, r));
    for (int k = 0; k < 3; ++k) acc[k] = p.alin[k] + ar[k] + wwr[k];
  }
}

bool valid_name(const std::string& s) {
  if (s.empty()) return false;
  for (char ch : s)
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-')) return false;
  return true;
}

}  // namespace

std::vector<Index> select_vertices(const Mesh& mesh, const Params& e) {
  std::vector<Index> vs;
  const Index n = mesh.num_vertices();
  if (e.is_scalar()) return named_group(mesh, e.as_string(), e);
  if (!e.is_map()) e.fail("a vertex selection is a group name (top_edge, ...) or a mapping with 'group', 'vertices' or 'box'.");
  if (e.has("group")) {
    Params g = e.child("group");
    vs = named_group(mesh, g.as_string(), g);
  }
  if (e.has("vertices")) {
    Params list = e.child("vertices");
    if (!list.is_sequence()) list.fail("must be a list of vertex indices.");
    for (std::size_t q = 0; q < list.size(); ++q) {
      const auto idx = list.at(q).as_int();
      if (idx < 0 || idx >= n)
        list.at(q).fail("vertex index " + std::to_string(idx) + " is out of range (the mesh has " +
                        std::to_string(n) + " vertices, numbered from 0).");
      vs.push_back(static_cast<Index>(idx));
    }
  }
  if (e.has("box")) {
    const auto b = box_vertices(mesh, e.child("box"));
    vs.insert(vs.end(), b.begin(), b.end());
  }
  if (vs.empty()) e.fail("the entry selects no vertex: give 'group' (a name such as top_edge), 'vertices' ([i, j, ...]) "
                         "or 'box' ({min: [x, y, z], max: [x, y, z]}).");
  std::sort(vs.begin(), vs.end());
  vs.erase(std::unique(vs.begin(), vs.end()), vs.end());
  return vs;
}

PinSet PinSet::parse(const Params& list, const Mesh& mesh, State& state) {
  PinSet set;
  if (!list.valid()) return set;
  if (!list.is_sequence())
    list.fail("must be a list, e.g. pins: [top_corners] or pins: [{name: clamp, vertices: [0, 31], motion: {type: translate, velocity: [0.01, 0, 0]}}].");
  std::vector<int> owner(static_cast<std::size_t>(mesh.num_vertices()), -1);
  for (std::size_t k = 0; k < list.size(); ++k) {
    const Params e = with_section_spec(list.at(k), "pins");  // its keys: section_specs.cpp
    if (!e.is_scalar() && !e.is_map())
      e.fail("a pin entry is a group name (top_corners, ...) or a mapping {name, group | vertices | box, motion}.");
    PinGroup g;
    std::vector<Index> vs = select_vertices(mesh, e);
    if (e.is_scalar()) {
      g.name = e.as_string();
    } else {
      const std::string def = e.has("group") ? e.child("group").as_string() : "pin" + std::to_string(k);
      g.name = e.get("name", def);
      if (!valid_name(g.name))
        e.child("name").fail("pin group name '" + g.name + "' is not usable as a stats.csv column; use letters, digits, '_' or '-'.");
      Params m = e.child("motion");
      if (m.valid()) {
        g.motion = parse_rigid_motion(m, {"center"});
        // The rotation axis passes through `center` (default: the group's centroid at t = 0).
        Params c = m.child("center");
        if (c.valid()) {
          g.center = read3(c, "center");
        } else {
          Vec3 s{0, 0, 0};
          for (Index i : vs)
            for (int q = 0; q < 3; ++q) s[q] += state.x[3 * static_cast<std::size_t>(i) + q] / static_cast<double>(vs.size());
          g.center = s;
        }
      }
      e.check_unused();
    }
    for (const auto& other : set.groups_)
      if (other.name == g.name)
        e.fail("two pin groups are named '" + g.name + "'; names label the reaction columns in stats.csv. Fix: give "
               "each group its own 'name'.");
    std::vector<Index> own;
    for (Index i : vs) {
      const int o = owner[static_cast<std::size_t>(i)];
      if (o < 0) {
        owner[static_cast<std::size_t>(i)] = static_cast<int>(set.groups_.size());
        own.push_back(i);
      } else if (g.moving() || set.groups_[static_cast<std::size_t>(o)].moving()) {
        e.fail("vertex " + std::to_string(i) + " is in pin groups '" + set.groups_[static_cast<std::size_t>(o)].name +
               "' and '" + g.name + "', and one of them moves: a vertex follows one motion. Fix: make the "
               "selections disjoint (e.g. shrink a box).");
      }
    }
    g.vertices = std::move(own);
    set.add(std::move(g), state);
  }
  return set;
}

void PinSet::add(PinGroup g, State& s) {
  std::sort(g.vertices.begin(), g.vertices.end());
  g.vertices.erase(std::unique(g.vertices.begin(), g.vertices.end()), g.vertices.end());
  g.rest.resize(3 * g.vertices.size());
  for (std::size_t k = 0; k < g.vertices.size(); ++k) {
    const Index i = g.vertices[k];
    s.pin(i);
    for (int q = 0; q < 3; ++q) g.rest[3 * k + q] = s.x[3 * static_cast<std::size_t>(i) + q];
  }
  moving_ = moving_ || g.moving();
  groups_.push_back(std::move(g));
  if (groups_.back().moving()) {
    // Place the new group at the current time (positions and velocities).
    const PinGroup& gg = groups_.back();
    const Placement p = placement(gg, s.time);
    for (std::size_t k = 0; k < gg.vertices.size(); ++k) {
      const std::size_t o = 3 * static_cast<std::size_t>(gg.vertices[k]);
      place_point(p, gg.center, &gg.rest[3 * k], &s.x[o], &s.v[o], nullptr);
    }
  }
}

void PinSet::evaluate(const PinGroup& g, std::size_t k, double t, double* x, double* v, double* a) const {
  if (!g.moving()) {
    for (int q = 0; q < 3; ++q) {
      x[q] = g.rest[3 * k + q];
      if (v) v[q] = 0;
      if (a) a[q] = 0;
    }
    return;
  }
  place_point(placement(g, t), g.center, &g.rest[3 * k], x, v, a);
}

void PinSet::place(double t, double* x, double* v) const {
  if (!moving_) return;
  for (const PinGroup& g : groups_) {
    if (!g.moving()) continue;
    const Placement p = placement(g, t);
    const std::size_t m = g.vertices.size();
    for (std::size_t k = 0; k < m; ++k) {
      const std::size_t o = 3 * static_cast<std::size_t>(g.vertices[k]);
      place_point(p, g.center, &g.rest[3 * k], x + o, v + o, nullptr);
    }
  }
}

void PinSet::apply_positions(State& s, double t) const {
  if (!moving_) return;
  for (const PinGroup& g : groups_) {
    if (!g.moving()) continue;
    const Placement p = placement(g, t);
    for (std::size_t k = 0; k < g.vertices.size(); ++k) {
      const std::size_t o = 3 * static_cast<std::size_t>(g.vertices[k]);
      place_point(p, g.center, &g.rest[3 * k], &s.x[o], nullptr, nullptr);
    }
  }
}

void PinSet::write_dv(const State& s, double t1, double h, std::span<double> z) const {
  for (Index i : s.pin_list) {
    const std::size_t o = 3 * static_cast<std::size_t>(i);
    z[o] = -s.v[o];
    z[o + 1] = -s.v[o + 1];
    z[o + 2] = -s.v[o + 2];
  }
  if (!moving_) return;
  const double inv_h = 1.0 / h;
  for (const PinGroup& g : groups_) {
    if (!g.moving()) continue;
    const Placement p = placement(g, t1);
    for (std::size_t k = 0; k < g.vertices.size(); ++k) {
      const std::size_t o = 3 * static_cast<std::size_t>(g.vertices[k]);
      double x1[3];
      place_point(p, g.center, &g.rest[3 * k], x1, nullptr, nullptr);
      // v1 = (x1 - x0)/h: the backward-Euler position update x0 + h v1 then lands on x1.
      for (int q = 0; q < 3; ++q) z[o + q] = (x1[q] - s.x[o + q]) * inv_h - s.v[o + q];
    }
  }
}

void PinSet::reactions(const State& s, const Material& material, const std::array<double, 3>& gravity,
                       std::vector<double>& work, std::vector<double>& out) const {
  out.assign(3 * groups_.size(), 0.0);
  if (groups_.empty()) return;
  const bool recorded = constraint_time_ == s.time && constraint_force_.size() == 3 * s.pin_list.size();
  if (recorded) {
    for (std::size_t gi = 0; gi < groups_.size(); ++gi)
      for (Index i : groups_[gi].vertices) {
        const auto it = std::lower_bound(s.pin_list.begin(), s.pin_list.end(), i);
        const std::size_t slot = static_cast<std::size_t>(it - s.pin_list.begin());
        for (int q = 0; q < 3; ++q) out[3 * gi + q] += constraint_force_[3 * slot + q];
      }
    return;
  }
  work.resize(s.x.size());
  material.compute_forces(s.x, s.v, work);
  for (std::size_t gi = 0; gi < groups_.size(); ++gi) {
    const PinGroup& g = groups_[gi];
    const Placement p = placement(g, s.time);
    for (std::size_t k = 0; k < g.vertices.size(); ++k) {
      const Index i = g.vertices[k];
      const std::size_t o = 3 * static_cast<std::size_t>(i);
      double x[3], a[3] = {0, 0, 0};
      if (g.moving()) place_point(p, g.center, &g.rest[3 * k], x, nullptr, a);
      const double m = s.mass[static_cast<std::size_t>(i)];
      for (int q = 0; q < 3; ++q) out[3 * gi + q] += m * a[q] - work[o + q] - m * gravity[q];
    }
  }
}

std::string PinSet::csv_header() const {
  std::string h;
  for (const PinGroup& g : groups_) h += ",pin_" + g.name + "_fx,pin_" + g.name + "_fy,pin_" + g.name + "_fz";
  return h;
}

}  // namespace loom
