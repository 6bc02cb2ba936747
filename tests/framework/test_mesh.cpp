#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <unistd.h>

#include "common/tube_obj.hpp"
#include "loom/mesh.hpp"
#include "loom/output.hpp"

namespace {
// The process id in the name: ctest runs each test in its own process, two at a time, and tests
// that wrote the same name raced (one read the other's bad.obj under the sanitizers).
std::string write_temp(const std::string& name, const std::string& text) {
  const auto p = std::filesystem::temp_directory_path() / ("loom_test_" + std::to_string(::getpid()) + "_" + name);
  std::ofstream(p) << text;
  return p.string();
}
std::string obj_error(const std::string& text) {
  const std::string path = write_temp("bad.obj", text);
  try {
    loom::read_obj(path);
  } catch (const loom::InputError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(Mesh, GridCountsAndGeometry) {
  const loom::Mesh m = loom::make_grid(4, 3, 3.0, 2.0);
  EXPECT_EQ(m.num_vertices(), 12);
  EXPECT_EQ(m.num_triangles(), 2 * 3 * 2);
  // (nx-1)(ny) + nx(ny-1) + diagonals (nx-1)(ny-1)
  EXPECT_EQ(m.edges().size(), 3u * 3 + 4 * 2 + 3 * 2);
  ASSERT_TRUE(m.grid.has_value());
  const loom::Index top_right = m.grid->index(3, 2);
  EXPECT_DOUBLE_EQ(m.positions[3 * top_right], 3.0);
  EXPECT_DOUBLE_EQ(m.positions[3 * top_right + 1], 2.0);
  // every triangle counter-clockwise in the xy plane (positive signed area)
  for (loom::Index t = 0; t < m.num_triangles(); ++t) {
    const auto* T = &m.triangles[3 * t];
    const double* a = &m.positions[3 * T[0]];
    const double* b = &m.positions[3 * T[1]];
    const double* c = &m.positions[3 * T[2]];
    EXPECT_GT((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]), 0.0);
  }
}

TEST(Mesh, GridRejectsBadSizes) {
  EXPECT_THROW(loom::make_grid(1, 5, 1, 1), loom::InputError);
  EXPECT_THROW(loom::make_grid(5, 5, 0, 1), loom::InputError);
  EXPECT_THROW(loom::make_grid(5, 5, 1, std::nan("")), loom::InputError);
}

TEST(Mesh, ObjReadsQuadsUvsAndNegativeIndices) {
  const std::string path = write_temp("quad.obj",
                                      "# quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                                      "f 1/1 2/2 3/3 4/4\nf -4/2 -1/1 -3/3\n");
  const loom::Mesh m = loom::read_obj(path);
  EXPECT_EQ(m.num_vertices(), 5);
  EXPECT_EQ(m.triangles[6], 1);  // -4 of 5 vertices is vertex 2 (index 1)
  EXPECT_EQ(m.triangles[7], 4);  // -1 is the last vertex
  EXPECT_EQ(m.num_triangles(), 3);
  ASSERT_EQ(m.uvs.size(), 10u);
  EXPECT_DOUBLE_EQ(m.uvs[2 * 2], 1.0);
}

TEST(Mesh, ObjCornerUvsFollowEachFaceAcrossASeamAndVertexUvsKeepTheFirstUse) {
  const tube_test::Tube tube{.N = 5, .M = 3, .shear = 0.25};
  const loom::Mesh m = loom::read_obj(tube.write("loader"));
  const int N = tube.N;
  ASSERT_EQ(m.num_triangles(), 2 * N * (tube.M - 1));
  ASSERT_EQ(m.uvs.size(), 2u * N * tube.M);
  ASSERT_EQ(m.corner_uvs.size(), 6u * m.num_triangles());
  EXPECT_TRUE(m.has_uvs());
  // Quad (r, c) is fanned into triangles 2 (r N + c) (corners (r,c) (r,c+1) (r+1,c+1)) and
  // 2 (r N + c) + 1 (corners (r,c) (r+1,c+1) (r+1,c)). Each corner carries the face's own vt:
  // u = c / N, and u = 1 (v shifted by the shear) at column N on the closing quads.
  for (int r = 0; r + 1 < tube.M; ++r)
    for (int c = 0; c < N; ++c) {
      const int corners[2][3][2] = {{{r, c}, {r, c + 1}, {r + 1, c + 1}}, {{r, c}, {r + 1, c + 1}, {r + 1, c}}};
      for (int h = 0; h < 2; ++h) {
        const loom::Index t = 2 * (r * N + c) + h;
        for (int k = 0; k < 3; ++k) {
          const int rr = corners[h][k][0], cc = corners[h][k][1];
          EXPECT_EQ(m.triangles[3 * t + k], tube.vertex(rr, cc % N));
          const double* w = m.corner_uv(t, k);
          EXPECT_EQ(w[0], cc == N ? 1.0 : tube.u(cc)) << "triangle " << t << " corner " << k;
          EXPECT_DOUBLE_EQ(w[1], tube.v(rr, cc)) << "triangle " << t << " corner " << k;
        }
      }
    }
  // One uv per vertex: the first use, u = 0 on the seam.
  for (int r = 0; r < tube.M; ++r) {
    EXPECT_EQ(m.uvs[2 * tube.vertex(r, 0)], 0.0);
    EXPECT_DOUBLE_EQ(m.uvs[2 * tube.vertex(r, 0) + 1], tube.v(r, 0));
  }
  // A face without vt takes each vertex's first-use vt at its corners.
  const loom::Mesh mix = loom::read_obj(write_temp("mixvt.obj",
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0.5 0.25\nvt 0.75 0.25\nvt 0.75 0.5\nvt 0.9 0.9\n"
      "f 1/1 2/2 3/3\nf 1 3 4/4\n"));
  ASSERT_EQ(mix.corner_uvs.size(), 12u);
  EXPECT_EQ(mix.corner_uv(1, 0)[0], 0.5);
  EXPECT_EQ(mix.corner_uv(1, 1)[1], 0.5);
  EXPECT_EQ(mix.corner_uv(1, 2)[0], 0.9);
  // No vt at all: neither.
  const loom::Mesh none = loom::read_obj(write_temp("novt.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n"));
  EXPECT_TRUE(none.uvs.empty());
  EXPECT_TRUE(none.corner_uvs.empty());
  EXPECT_FALSE(none.has_uvs());
}

namespace {
int count_vt_lines(const std::string& obj) {
  int vt = 0;
  std::istringstream in(obj);
  for (std::string line; std::getline(in, line);)
    if (line.rfind("vt ", 0) == 0) ++vt;
  return vt;
}
}  // namespace

TEST(Mesh, ObjOutputKeepsUvSeamsAndReadsBackTheSameCornerUvs) {
  // The tube's seam: M vertices (column 0) whose closing-quad corners carry u = 1 (and v
  // shifted by the shear) where their first use has u = 0. Written with uvs, the OBJ must give
  // those corners their own vt (M more than the N M per-vertex ones, by the construction) and
  // read back to the same per-corner and per-vertex uvs, bit for bit with lossless numbers.
  const tube_test::Tube tube{.N = 6, .M = 4, .shear = 0.25};
  const loom::Mesh m = loom::read_obj(tube.write("writer"));
  loom::ObjOptions o;
  o.uvs = true;
  o.lossless = true;
  const std::string text = loom::obj_text(m, m.positions, "seam", o);
  EXPECT_EQ(count_vt_lines(text), tube.N * tube.M + tube.M);
  const loom::Mesh back = loom::read_obj(write_temp("seam_back.obj", text));
  EXPECT_EQ(back.triangles, m.triangles);
  EXPECT_EQ(back.positions, m.positions);
  EXPECT_EQ(back.uvs, m.uvs);
  ASSERT_EQ(back.corner_uvs.size(), m.corner_uvs.size());
  EXPECT_EQ(back.corner_uvs, m.corner_uvs);
  // Spot check against the construction: the closing quad of ring 0 has u = 1 at column N.
  const loom::Index t = 2 * (tube.N - 1);  // quad (0, N - 1), first triangle: (0,N-1) (0,N) (1,N)
  EXPECT_EQ(back.corner_uv(t, 1)[0], 1.0);
  EXPECT_EQ(back.corner_uv(t, 2)[0], 1.0);
  EXPECT_EQ(back.uvs[2 * tube.vertex(0, 0)], 0.0);

  // Without seams (a quad whose faces agree on every vertex's vt): one vt per vertex and f v/v,
  // as before.
  const loom::Mesh flat = loom::read_obj(write_temp("noseam.obj",
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"));
  const std::string flat_text = loom::obj_text(flat, flat.positions, "", o);
  EXPECT_NE(flat_text.find("f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"), std::string::npos) << flat_text;
  EXPECT_EQ(count_vt_lines(flat_text), 4);
}

TEST(Mesh, GridCornerUvsAreTheVertexUvs) {
  const loom::Mesh g = loom::make_grid(4, 3, 0.3, 0.2);
  EXPECT_TRUE(g.corner_uvs.empty());  // no seams: corner_uv() reads the vertex uvs
  ASSERT_TRUE(g.has_uvs());
  for (loom::Index t = 0; t < g.num_triangles(); ++t)
    for (int k = 0; k < 3; ++k) {
      const loom::Index i = g.triangles[3 * t + k];
      // uv = the in-plane position (x, y) of the XY grid
      EXPECT_EQ(g.corner_uv(t, k)[0], g.positions[3 * i]);
      EXPECT_EQ(g.corner_uv(t, k)[1], g.positions[3 * i + 1]);
    }
}

TEST(Mesh, ObjErrorsNameFileLineAndFix) {
  std::string e = obj_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
  EXPECT_NE(e.find("bad.obj:4"), std::string::npos) << e;
  EXPECT_NE(e.find("out of range"), std::string::npos) << e;
  e = obj_error("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
  EXPECT_NE(e.find("bad.obj:2"), std::string::npos) << e;
  EXPECT_NE(e.find("NaN"), std::string::npos) << e;
  e = obj_error("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 4\nf 1 2 3\n");
  EXPECT_NE(e.find("bad.obj:6"), std::string::npos) << e;
  EXPECT_NE(e.find("degenerate"), std::string::npos) << e;
  e = obj_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 1 2\n");
  EXPECT_NE(e.find("repeated"), std::string::npos) << e;
  e = obj_error("v 0 0 0\n");
  EXPECT_NE(e.find("no faces"), std::string::npos) << e;
  e = obj_error("v 0 0\n");
  EXPECT_NE(e.find("bad.obj:1"), std::string::npos) << e;
  EXPECT_THROW(loom::read_obj("/nonexistent.obj"), loom::InputError);
}

// Issue 20: CR-only (old Mac) and CRLF files read like LF files; a subnormal coordinate is a
// number; a folder is not an OBJ file.
TEST(Mesh, ObjLineEndingsSubnormalsAndFolders) {
  const std::string lf = "v 0 0 0\nv 1 0 0\nv 0 1 4e-320\nf 1 2 3\n";
  std::string cr = lf, crlf;
  for (char& c : cr)
    if (c == '\n') c = '\r';
  for (char c : lf) crlf += c == '\n' ? std::string("\r\n") : std::string(1, c);
  for (const auto& [name, text] : {std::pair{"lf.obj", lf}, std::pair{"cr.obj", cr}, std::pair{"crlf.obj", crlf}}) {
    const loom::Mesh m = loom::read_obj(write_temp(name, text));
    EXPECT_EQ(m.num_vertices(), 3) << name;
    EXPECT_EQ(m.num_triangles(), 1) << name;
    EXPECT_EQ(m.positions[8], 4e-320) << name;
    EXPECT_GT(m.positions[8], 0.0);  // really subnormal, not flushed
  }
  EXPECT_NE(obj_error("v 0 0 0\nv 1 0 0\nv 0 1 1e999\nf 1 2 3\n").find("NaN or Inf"), std::string::npos);
  try {
    loom::read_obj(std::filesystem::temp_directory_path().string());
    FAIL() << "a folder was read as an OBJ file";
  } catch (const loom::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("not a regular file"), std::string::npos) << e.what();
  }
}

// Issue 20: a concave n-gon that a fan would split into a flipped triangle, and duplicate
// faces, are errors naming the line; a non-manifold edge is accepted (with a warning).
TEST(Mesh, ObjTopologyProblemsAreReported) {
  // an L-shaped hexagon, fanned from its reflex corner's neighbour: concave
  const std::string concave = "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\nf 3 4 5 6 1 2\n";
  std::string e = obj_error(concave);
  EXPECT_NE(e.find(":7:"), std::string::npos) << e;
  EXPECT_NE(e.find("not convex"), std::string::npos) << e;
  // the same outline fanned from a vertex that sees every other one is fine
  const loom::Mesh ok = loom::read_obj(write_temp("convexfan.obj", "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\nf 4 5 6 1 2 3\n"));
  EXPECT_EQ(ok.num_triangles(), 4);
  // a convex quad
  EXPECT_EQ(loom::read_obj(write_temp("quad2.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")).num_triangles(), 2);
  e = obj_error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 2 3 1\n");
  EXPECT_NE(e.find(":5:"), std::string::npos) << e;
  EXPECT_NE(e.find("duplicate face"), std::string::npos) << e;
  EXPECT_NE(e.find("line 4"), std::string::npos) << e;
  // three triangles on one edge: read (a warning goes to stderr)
  const loom::Mesh nm = loom::read_obj(
      write_temp("nonmanifold.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nf 1 2 3\nf 2 1 4\nf 1 2 5\n"));
  EXPECT_EQ(nm.num_triangles(), 3);
}
