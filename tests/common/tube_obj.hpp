// An OBJ tube with a wrapping UV seam, for the tests of per-corner texture coordinates.
//
// N columns around the z axis, M rings (vertex (r, c) at (R cos(2 pi c / N), R sin(2 pi c / N),
// r dz), OBJ index r N + c + 1), quads (r, c) (r, c+1) (r+1, c+1) (r+1, c) facing outward (the
// loader fans them into (r,c)(r,c+1)(r+1,c+1) and (r,c)(r+1,c+1)(r+1,c)). Texture coordinates:
// u = c / N, v = r / M + shear * c / N (shear != 0: the weft runs around the tube as a helix).
// The closing quads (c = N-1) use separate vt entries at the seam vertices (c = 0): u = 1.0,
// v = r / M + shear, as a modelling tool writes a cut tube. Faces are written from c = 0, so the
// first use of a seam vertex has u = 0.
#pragma once

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <unistd.h>

namespace tube_test {

struct Tube {
  int N = 12, M = 5;
  double R = 0.1, dz = 0.05, shear = 0.0;

  double angle(int c) const { return 2.0 * std::numbers::pi * c / N; }
  int vertex(int r, int c) const { return r * N + c; }  // 0-based
  double u(int c) const { return double(c) / N; }
  double v(int r, int c) const { return double(r) / M + shear * c / N; }

  std::string obj_text() const {
    std::ostringstream s;
    s.precision(17);
    for (int r = 0; r < M; ++r)
      for (int c = 0; c < N; ++c) s << "v " << R * std::cos(angle(c)) << ' ' << R * std::sin(angle(c)) << ' ' << r * dz << '\n';
    for (int r = 0; r < M; ++r)
      for (int c = 0; c < N; ++c) s << "vt " << u(c) << ' ' << v(r, c) << '\n';
    for (int r = 0; r < M; ++r) s << "vt 1.0 " << v(r, N) << '\n';  // seam copies: vt N M + r + 1
    auto vi = [&](int r, int c) { return vertex(r, c % N) + 1; };
    auto ti = [&](int r, int c) { return c == N ? N * M + r + 1 : r * N + c + 1; };
    for (int r = 0; r + 1 < M; ++r)
      for (int c = 0; c < N; ++c)
        s << "f " << vi(r, c) << '/' << ti(r, c) << ' ' << vi(r, c + 1) << '/' << ti(r, c + 1) << ' ' << vi(r + 1, c + 1)
          << '/' << ti(r + 1, c + 1) << ' ' << vi(r + 1, c) << '/' << ti(r + 1, c) << '\n';
    return s.str();
  }

  std::string write(const std::string& name) const {
    const auto p = std::filesystem::temp_directory_path() /
                   ("loom_tube_" + std::to_string(::getpid()) + "_" + name + ".obj");
    std::ofstream(p) << obj_text();
    return p.string();
  }
};

}  // namespace tube_test
