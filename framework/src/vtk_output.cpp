#include "loom/vtk_output.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "loom/output.hpp"

namespace fs = std::filesystem;

namespace loom {

namespace {

void put_exact(std::string& s, double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);  // shortest round-trip decimal
  s.append(buf, r.ptr);
}

void put_int(std::string& s, long long v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  s.append(buf, r.ptr);
}

// A Float64 array of n tuples of `comps` components, six tuples' worth of numbers a line.
void put_array(std::string& s, const char* name, int comps, std::span<const double> a) {
  s += "        <DataArray type=\"Float64\"";
  if (name) {
    s += " Name=\"";
    s += name;
    s += '"';
  }
  s += " NumberOfComponents=\"";
  put_int(s, comps);
  s += "\" format=\"ascii\">\n";
  for (std::size_t i = 0; i < a.size(); ++i) {
    s += (i % (6 * static_cast<std::size_t>(comps)) == 0) ? "          " : " ";
    put_exact(s, a[i]);
    if (i + 1 == a.size() || (i + 1) % (6 * static_cast<std::size_t>(comps)) == 0) s += '\n';
  }
  s += "        </DataArray>\n";
}

}  // namespace

bool uv_seam_free(const Mesh& mesh) {
  const std::size_t n = static_cast<std::size_t>(mesh.num_vertices());
  if (n == 0 || mesh.uvs.size() != 2 * n) return false;
  if (mesh.corner_uvs.size() != 2 * mesh.triangles.size()) return true;  // no per-corner uvs: none differ
  for (std::size_t c = 0; c < mesh.triangles.size(); ++c) {
    const std::size_t v = 2 * static_cast<std::size_t>(mesh.triangles[c]);
    if (mesh.corner_uvs[2 * c] != mesh.uvs[v] || mesh.corner_uvs[2 * c + 1] != mesh.uvs[v + 1]) return false;
  }
  return true;
}

std::string vtu_frame_name(int frame) {
  char name[32];
  std::snprintf(name, sizeof(name), "frame_%05d.vtu", frame);
  return name;
}

VtkSeriesWriter::VtkSeriesWriter(const std::string& dir, const Mesh& mesh, bool uvs)
    : dir_(dir), mesh_(mesh), uvs_(uvs && uv_seam_free(mesh)) {
  edges_ = mesh.edges();
  rest_length_.resize(edges_.size());
  const auto& p = mesh.positions;
  for (std::size_t e = 0; e < edges_.size(); ++e) {
    const std::size_t a = 3 * static_cast<std::size_t>(edges_[e][0]), b = 3 * static_cast<std::size_t>(edges_[e][1]);
    rest_length_[e] = std::sqrt((p[b] - p[a]) * (p[b] - p[a]) + (p[b + 1] - p[a + 1]) * (p[b + 1] - p[a + 1]) +
                                (p[b + 2] - p[a + 2]) * (p[b + 2] - p[a + 2]));
  }
  strain_.resize(static_cast<std::size_t>(mesh.num_vertices()));
}

std::string VtkSeriesWriter::vtu_text(double time, std::span<const double> x, std::span<const double> v,
                                      std::span<const double> gap) {
  const std::size_t n = static_cast<std::size_t>(mesh_.num_vertices());
  const std::size_t m = static_cast<std::size_t>(mesh_.num_triangles());
  std::fill(strain_.begin(), strain_.end(), 0.0);
  for (std::size_t e = 0; e < edges_.size(); ++e) {
    if (!(rest_length_[e] > 0)) continue;
    const std::size_t a = 3 * static_cast<std::size_t>(edges_[e][0]), b = 3 * static_cast<std::size_t>(edges_[e][1]);
    const double l = std::sqrt((x[b] - x[a]) * (x[b] - x[a]) + (x[b + 1] - x[a + 1]) * (x[b + 1] - x[a + 1]) +
                               (x[b + 2] - x[a + 2]) * (x[b + 2] - x[a + 2]));
    const double s = std::abs(l / rest_length_[e] - 1.0);
    for (Index k : edges_[e]) strain_[static_cast<std::size_t>(k)] = std::max(strain_[static_cast<std::size_t>(k)], s);
  }
  std::string s;
  s.reserve(n * (v.empty() ? 80 : 150) + (uvs_ ? n * 40 : 0) + m * 24 + 1024);
  s += "<?xml version=\"1.0\"?>\n"
       "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
       "  <UnstructuredGrid>\n"
       "    <FieldData>\n"
       "      <DataArray type=\"Float64\" Name=\"TimeValue\" NumberOfTuples=\"1\" format=\"ascii\">";
  put_exact(s, time);
  s += "</DataArray>\n    </FieldData>\n    <Piece NumberOfPoints=\"";
  put_int(s, static_cast<long long>(n));
  s += "\" NumberOfCells=\"";
  put_int(s, static_cast<long long>(m));
  s += "\">\n      <PointData Scalars=\"strain\"";
  if (!v.empty()) s += " Vectors=\"velocity\"";
  if (uvs_) s += " TCoords=\"uv\"";
  s += ">\n";
  put_array(s, "strain", 1, strain_);
  if (uvs_) put_array(s, "uv", 2, mesh_.uvs);
  if (!v.empty()) put_array(s, "velocity", 3, v);
  if (!gap.empty()) {
    put_array(s, "collider_gap", 1, gap);
    contact_.resize(gap.size());
    for (std::size_t i = 0; i < gap.size(); ++i) contact_[i] = gap[i] <= kContactGap ? 1.0 : 0.0;
    put_array(s, "contact", 1, contact_);
  }
  s += "      </PointData>\n      <Points>\n";
  put_array(s, "Points", 3, x);
  s += "      </Points>\n      <Cells>\n        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n";
  for (std::size_t t = 0; t < m; ++t) {
    s += (t % 8 == 0) ? "          " : " ";
    put_int(s, mesh_.triangles[3 * t]);
    s += ' ';
    put_int(s, mesh_.triangles[3 * t + 1]);
    s += ' ';
    put_int(s, mesh_.triangles[3 * t + 2]);
    if (t + 1 == m || (t + 1) % 8 == 0) s += '\n';
  }
  s += "        </DataArray>\n        <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n";
  for (std::size_t t = 0; t < m; ++t) {
    s += (t % 16 == 0) ? "          " : " ";
    put_int(s, 3 * static_cast<long long>(t + 1));
    if (t + 1 == m || (t + 1) % 16 == 0) s += '\n';
  }
  s += "        </DataArray>\n        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
  for (std::size_t t = 0; t < m; ++t) {
    s += (t % 32 == 0) ? "          5" : " 5";
    if (t + 1 == m || (t + 1) % 32 == 0) s += '\n';
  }
  s += "        </DataArray>\n      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n";
  return s;
}

std::string VtkSeriesWriter::pvd_text() const {
  std::string s =
      "<?xml version=\"1.0\"?>\n"
      "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
      "  <Collection>\n";
  for (const Entry& e : entries_) {
    s += "    <DataSet timestep=\"";
    put_exact(s, e.time);
    s += "\" part=\"0\" file=\"" + vtu_frame_name(e.frame) + "\"/>\n";
  }
  s += "  </Collection>\n</VTKFile>\n";
  return s;
}

int VtkSeriesWriter::adopt_existing(int last_frame) {
  entries_.clear();
  std::ifstream in(fs::path(dir_) / "run.pvd");
  std::string line;
  while (std::getline(in, line)) {
    const auto ts = line.find("timestep=\""), file = line.find("file=\"frame_");
    if (ts == std::string::npos || file == std::string::npos) continue;
    Entry e{};
    const char* p = line.c_str() + ts + 10;
    const auto r = std::from_chars(p, line.c_str() + line.size(), e.time);
    const char* q = line.c_str() + file + 12;
    const auto r2 = std::from_chars(q, line.c_str() + line.size(), e.frame);
    if (r.ec != std::errc() || r2.ec != std::errc() || e.frame > last_frame) continue;
    entries_.push_back(e);
  }
  return static_cast<int>(entries_.size());
}

void VtkSeriesWriter::write_frame(int frame, double time, std::span<const double> x, std::span<const double> v,
                                  std::span<const double> gap) {
  write_file_atomic((fs::path(dir_) / vtu_frame_name(frame)).string(), vtu_text(time, x, v, gap));
  entries_.push_back({frame, time});
  write_file_atomic((fs::path(dir_) / "run.pvd").string(), pvd_text());
}

}  // namespace loom
