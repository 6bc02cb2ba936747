// loom-material-curves: print a material file's curves as Loom uses them (after the
// conversion to the model's measure), for plotting (scripts/plot_material.py).
//   loom-material-curves FILE [--interpolation monotone_cubic|bspline] [--points N] [--beyond F]
// CSV on stdout: curve,kind,strain,stress,stiffness,energy
//   kind = sample (the file's samples, converted), data (the interpolant inside the samples),
//          extension (the linear continuation, F times the data range on each side).
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include "loom/common.hpp"
#include "material_file.hpp"

int main(int argc, char** argv) {
  std::string file, interp = "monotone_cubic";
  int points = 400;
  double beyond = 0.25;
  for (int a = 1; a < argc; ++a) {
    const std::string s = argv[a];
    auto next = [&]() -> std::string {
      if (a + 1 >= argc) {
        std::fprintf(stderr, "loom-material-curves: %s needs a value\n", s.c_str());
        std::exit(2);
      }
      return argv[++a];
    };
    if (s == "--interpolation") interp = next();
    else if (s == "--points") points = std::atoi(next().c_str());
    else if (s == "--beyond") beyond = std::atof(next().c_str());
    else if (s == "--help" || s == "-h") {
      std::printf("usage: loom-material-curves FILE [--interpolation monotone_cubic|bspline] [--points N] [--beyond F]\n");
      return 0;
    } else if (file.empty()) file = s;
    else {
      std::fprintf(stderr, "loom-material-curves: unexpected argument '%s'\n", s.c_str());
      return 2;
    }
  }
  if (file.empty() || (interp != "monotone_cubic" && interp != "bspline") || points < 2 || !(beyond >= 0)) {
    std::fprintf(stderr, "usage: loom-material-curves FILE [--interpolation monotone_cubic|bspline] [--points N >= 2] [--beyond F >= 0]\n");
    return 2;
  }
  try {
    const auto kind = interp == "bspline" ? loom::CurveInterpolation::BSpline : loom::CurveInterpolation::MonotoneCubic;
    const loom::gnatv::MaterialData m = loom::gnatv::read_material_file(file, kind);
    std::printf("curve,kind,strain,stress,stiffness,energy\n");
    const std::pair<const char*, const loom::Curve*> curves[] = {{"weft", &m.weft}, {"warp", &m.warp}, {"shear", &m.shear}};
    for (const auto& [name, c] : curves) {
      for (std::size_t k = 0; k < c->size(); ++k) {
        const double e = c->strain()[k];
        std::printf("%s,sample,%.17g,%.17g,%.17g,%.17g\n", name, e, c->samples()[k], c->stiffness(e), c->energy(e));
      }
      const double lo = c->strain().front(), hi = c->strain().back(), range = hi - lo;
      const double a = lo - beyond * range, b = hi + beyond * range;
      for (int q = 0; q < points; ++q) {
        const double e = a + (b - a) * q / (points - 1);
        std::printf("%s,%s,%.17g,%.17g,%.17g,%.17g\n", name, (e < lo || e > hi) ? "extension" : "data", e, c->stress(e),
                    c->stiffness(e), c->energy(e));
      }
    }
  } catch (const loom::InputError& e) {
    std::fprintf(stderr, "loom-material-curves: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "loom-material-curves: %s\n", e.what());
    return 1;
  }
  return 0;
}
