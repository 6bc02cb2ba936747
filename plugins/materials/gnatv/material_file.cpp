#include "material_file.hpp"

#include <cmath>
#include <fstream>

#include "loom/params.hpp"

namespace loom::gnatv {
namespace {

const char* kMeasureFix =
    "Fix: add 'measure: nominal' (tensile: force per unit reference width, N/m, against engineering strain "
    "(l - L)/L, as a tensile tester reports it; shear: force per unit clamp length, N/m, against the shear angle "
    "in radians) or 'measure: green_pk2' (the model's own measure: second Piola-Kirchhoff stress, N/m, against "
    "Green-Lagrange strain; shear against u.v). materials/README.md explains both.";

Curve read_curve(const Params& curves, const std::string& key, CurveInterpolation kind, double scale,
                 std::string& measure_out) {
  if (!curves.has(key))
    curves.fail("missing curve '" + key + "'; a material file needs curves weft, warp and shear");
  const Params c = curves.child(key);
  if (!c.is_map())
    c.fail("curve '" + key + "' must be a mapping with measure, start, step and stress (or strain and stress)");
  const bool shear = key == "shear";
  // What the numbers are: no default, since a wrong guess silently changes the material.
  if (!c.has("measure")) c.fail("curve '" + key + "' does not say what it measures. " + kMeasureFix);
  const std::string measure = c.get_choice("measure", "green_pk2", {"nominal", "green_pk2"});
  measure_out = measure;
  const bool nominal = measure == "nominal";
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

  // The strain samples, and where each one is written (for messages).
  std::vector<double> strain;
  bool uniform = false;
  double start = 0, step = 0;
  Params xp;
  if (c.has("strain")) {
    if (c.has("start") || c.has("step"))
      c.fail("curve '" + key + "' gives both 'strain' and 'start'/'step'; give one of them");
    xp = c.child("strain");
    if (!xp.is_sequence()) xp.fail("'strain' of curve '" + key + "' must be a list of numbers");
    strain = xp.as_doubles();
    if (strain.size() != stress.size())
      xp.fail("curve '" + key + "' has " + std::to_string(strain.size()) + " strain and " +
              std::to_string(stress.size()) + " stress samples; they must match");
  } else {
    if (!c.has("start")) c.fail("curve '" + key + "' has no 'start' (strain of the first sample)");
    if (!c.has("step")) c.fail("curve '" + key + "' has no 'step' (strain between samples)");
    const Params st = c.child("step");
    start = c.child("start").as_double();
    step = st.as_double();
    if (!std::isfinite(start)) c.child("start").fail("'start' of curve '" + key + "' is not finite");
    if (!(step > 0) || !std::isfinite(step))
      st.fail("'step' of curve '" + key + "' must be positive (the strain grid must increase), got " +
              std::to_string(step));
    uniform = true;
    strain.resize(stress.size());
    for (std::size_t k = 0; k < strain.size(); ++k) strain[k] = start + step * static_cast<double>(k);
  }
  auto strain_node = [&](std::size_t k) { return uniform ? c.child("step") : xp.at(k); };
  // Percent instead of fractions (or degrees instead of radians): strains beyond 1 are not cloth.
  for (std::size_t k = 0; k < strain.size(); ++k)
    if (std::isfinite(strain[k]) && std::fabs(strain[k]) > 1.0)
      strain_node(k).fail("curve '" + key + "': strain sample " + std::to_string(k) + " is " +
                          std::to_string(strain[k]) + "; strains are fractions (0.05 = 5 %)" +
                          (shear && nominal ? " and shear angles radians" : "") +
                          ", so values above 1 are almost certainly percent" +
                          (shear && nominal ? " or degrees" : "") + ". Fix: divide the strains by 100" +
                          (shear && nominal ? " (degrees: multiply by pi/180)" : "") + ".");
  // A softening curve (stress falling as strain grows) is refused rather than warned about: a
  // negative slope is a negative stiffness, the implicit step's matrix loses definiteness
  // (NUMERICS.md 2.4) and the cloth tears where the slope is negative (Strohkorb 2019, fig. 7).
  // Lab data that dips is noise or a digitising slip, which the user must look at.
  for (std::size_t k = 1; k < stress.size(); ++k)
    if (stress[k] < stress[k - 1])
      sp.at(k).fail("curve '" + key + "' is not monotone: stress sample " + std::to_string(k) + " (" +
                    std::to_string(stress[k]) + ") is below sample " + std::to_string(k - 1) + " (" +
                    std::to_string(stress[k - 1]) + "). A falling stress is a negative stiffness: the implicit "
                    "solve loses definiteness and the cloth tears there. Fix: check the sample (a digitising or "
                    "unit slip?), or smooth the measurement so that stress never decreases with strain.");
  // Exact conversion to the model's measure (docs/NUMERICS.md, "What a curve measures").
  if (nominal) {
    for (std::size_t k = 0; k < strain.size(); ++k) {
      if (shear) {
        // trellis shear at constant fibre length: eps_uv = u.v = sin(phi), sigma_uv = F / B
        strain[k] = std::sin(strain[k]);
      } else {
        const double e = strain[k], lam = 1.0 + e;  // |e| <= 1 was checked; e = -1 is a collapsed fibre
        if (!(lam > 0)) strain_node(k).fail("curve '" + key + "': engineering strain -1 collapses the fabric to zero length.");
        strain[k] = e + 0.5 * e * e;    // Green-Lagrange E = (lambda^2 - 1)/2
        stress[k] = stress[k] / lam;    // PK2 S = P / lambda
      }
    }
    // End slopes for the B-spline: dS/dE = (P' lambda - P) / lambda^3, d sigma/d eps_uv = P' / cos(phi).
    auto convert_slope = [&](double slope, std::size_t k, double phi_or_e, double P) {
      if (!std::isfinite(slope)) return slope;
      if (shear) return slope / std::cos(phi_or_e);
      const double lam = 1.0 + phi_or_e;
      (void)k;
      return (slope * lam - P * scale) / (lam * lam * lam);
    };
    const std::vector<double> raw = sp.as_doubles();
    const double x0 = uniform ? start : xp.at(0).as_double();
    const double xn = uniform ? start + step * static_cast<double>(raw.size() - 1) : xp.at(raw.size() - 1).as_double();
    left = convert_slope(left, 0, x0, raw.front());
    right = convert_slope(right, raw.size() - 1, xn, raw.back());
    for (std::size_t k = 1; k < stress.size(); ++k)
      if (stress[k] < stress[k - 1])
        sp.at(k).fail("curve '" + key + "': converted to the model's measure (S = P / (1 + e)), stress sample " +
                      std::to_string(k) + " falls below sample " + std::to_string(k - 1) +
                      ": the force grows more slowly than the stretch there. Fix: check the samples and the measure.");
  }
  try {
    Curve out;
    try {
      out = uniform && !nominal ? Curve::build_uniform(start, step, stress, kind, left, right)
                                : Curve::build(strain, stress, kind, left, right);
    } catch (const CurveError& e) {
      if (!uniform && e.sample() >= 0 && static_cast<std::size_t>(e.sample()) < strain.size())
        xp.at(static_cast<std::size_t>(e.sample())).fail("curve '" + key + "': " + e.what());
      throw;
    }
    c.check_unused();
    // Every derived quantity must be finite where the model can evaluate it: samples near the
    // double range (1e308) or an infinite end slope would pass the sample checks and then give
    // Inf or NaN forces at the first step. Checked at the data's ends, at the samples, and a
    // data range beyond each end (the linear extension).
    {
      const double lo = strain.front(), hi = strain.back(), span = hi - lo;
      std::vector<double> probes = {lo - span, lo, 0.0, hi, hi + span};
      probes.insert(probes.end(), strain.begin(), strain.end());
      for (double e : probes) {
        const double W = out.energy(e), S = out.stress(e), D = out.stiffness(e);
        if (!std::isfinite(W) || !std::isfinite(S) || !std::isfinite(D))
          c.fail("curve '" + key + "' is not finite at strain " + std::to_string(e) + " (energy " + std::to_string(W) +
                 ", stress " + std::to_string(S) + ", stiffness " + std::to_string(D) +
                 "): a sample or an end slope is too large for the model to evaluate. Fix: check the units "
                 "(stress in N/m) and the bspline end slopes.");
      }
    }
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
  m.weft = read_curve(curves, "weft", kind, stress_scale, m.weft_measure);
  m.warp = read_curve(curves, "warp", kind, stress_scale, m.warp_measure);
  m.shear = read_curve(curves, "shear", kind, stress_scale, m.shear_measure);
  curves.check_unused();
  root.check_unused();
  return m;
}

}  // namespace loom::gnatv
