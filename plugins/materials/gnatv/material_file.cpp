#include "material_file.hpp"

#include <cmath>
#include <fstream>

#include "loom/params.hpp"

namespace loom::gnatv {
namespace {

Curve read_curve(const Params& curves, const std::string& key, CurveInterpolation kind, double scale) {
  if (!curves.has(key))
    curves.fail("missing curve '" + key + "'; a material file needs curves weft, warp and shear");
  const Params c = curves.child(key);
  if (!c.is_map())
    c.fail("curve '" + key + "' must be a mapping with start, step and stress (or strain and stress)");
  if (!c.has("stress")) c.fail("curve '" + key + "' has no 'stress' samples");
  const Params sp = c.child("stress");
  if (!sp.is_sequence()) sp.fail("'stress' of curve '" + key + "' must be a list of numbers");
  std::vector<double> stress = sp.as_doubles();
  for (std::size_t k = 0; k < stress.size(); ++k) {
    if (!std::isfinite(stress[k]))
      sp.at(k).fail("stress sample " + std::to_string(k) + " of curve '" + key + "' is not a finite number");
    stress[k] *= scale;
  }
  if (stress.size() < 2)
    sp.fail("curve '" + key + "' needs at least 2 stress samples, got " + std::to_string(stress.size()));
  double left = std::nan(""), right = std::nan("");
  if (c.has("bspline_left_slope")) left = c.child("bspline_left_slope").as_double() * scale;
  if (c.has("bspline_right_slope")) right = c.child("bspline_right_slope").as_double() * scale;
  if (c.has("note")) c.mark_used("note");
  try {
    Curve out;
    if (c.has("strain")) {
      if (c.has("start") || c.has("step"))
        c.fail("curve '" + key + "' gives both 'strain' and 'start'/'step'; give one of them");
      const Params xp = c.child("strain");
      if (!xp.is_sequence()) xp.fail("'strain' of curve '" + key + "' must be a list of numbers");
      std::vector<double> strain = xp.as_doubles();
      if (strain.size() != stress.size())
        xp.fail("curve '" + key + "' has " + std::to_string(strain.size()) + " strain and " +
                std::to_string(stress.size()) + " stress samples; they must match");
      try {
        out = Curve::build(strain, stress, kind, left, right);
      } catch (const CurveError& e) {
        if (e.sample() >= 0 && static_cast<std::size_t>(e.sample()) < strain.size())
          xp.at(static_cast<std::size_t>(e.sample())).fail("curve '" + key + "': " + e.what());
        throw;
      }
    } else {
      if (!c.has("start")) c.fail("curve '" + key + "' has no 'start' (strain of the first sample)");
      if (!c.has("step")) c.fail("curve '" + key + "' has no 'step' (strain between samples)");
      const Params st = c.child("step");
      const double start = c.child("start").as_double();
      const double step = st.as_double();
      if (!std::isfinite(start)) c.child("start").fail("'start' of curve '" + key + "' is not finite");
      if (!(step > 0) || !std::isfinite(step))
        st.fail("'step' of curve '" + key + "' must be positive (the strain grid must increase), got " +
                std::to_string(step));
      out = Curve::build_uniform(start, step, stress, kind, left, right);
    }
    c.check_unused();
    // The rest state (zero strain) must be stress free.
    double smax = 0;
    for (double s : stress) smax = std::max(smax, std::fabs(s));
    const double s0 = out.stress(0.0);
    if (std::fabs(s0) > 1e-9 * std::max(smax, 1e-300))
      c.fail("curve '" + key + "' gives stress " + std::to_string(s0) +
             " at zero strain; the rest state must be stress free: shift the samples so that "
             "stress(0) = 0");
    return out;
  } catch (const CurveError& e) {
    c.fail("curve '" + key + "': " + e.what());
  }
}

}  // namespace

MaterialData read_material_file(const std::string& path, CurveInterpolation kind, double stress_scale) {
  {
    std::ifstream probe(path);
    if (!probe) throw InputError(path + ": cannot open material file; check the material_file path "
                                 "(relative paths resolve against the scene file's folder)");
  }
  const Params root = Params::from_file(path);
  if (!root.is_map()) root.fail("a material file must be a YAML mapping (see materials/README.md)");
  MaterialData m;
  m.path = path;
  // "bending" (hinge bending data of a measured fabric) is read by the framework (loom/fabric_library.hpp).
  for (const char* k : {"name", "source", "units", "provenance", "notes", "bending"})
    if (root.has(k)) root.mark_used(k);
  if (root.has("name")) m.name = root.child("name").as_string();
  if (!root.has("areal_density")) root.fail("missing 'areal_density' (kg/m^2)");
  m.areal_density = root.child("areal_density").as_double();
  if (!(m.areal_density > 0) || !std::isfinite(m.areal_density))
    root.child("areal_density").fail("'areal_density' must be a positive number (kg/m^2)");
  if (!root.has("curves")) root.fail("missing 'curves' (with weft, warp and shear)");
  const Params curves = root.child("curves");
  if (!curves.is_map()) curves.fail("'curves' must be a mapping with weft, warp and shear");
  m.weft = read_curve(curves, "weft", kind, stress_scale);
  m.warp = read_curve(curves, "warp", kind, stress_scale);
  m.shear = read_curve(curves, "shear", kind, stress_scale);
  curves.check_unused();
  root.check_unused();
  return m;
}

}  // namespace loom::gnatv
