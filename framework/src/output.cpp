#include "loom/output.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <stdexcept>

#include "loom/common.hpp"

namespace fs = std::filesystem;

namespace loom {

void write_file_atomic(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) throw OutputError("cannot create " + tmp + ": " + std::strerror(errno));
  const std::size_t n = std::fwrite(text.data(), 1, text.size(), f);
  bool ok = n == text.size() && std::fflush(f) == 0;
  const int write_errno = errno;
  ok = std::fclose(f) == 0 && ok;
  if (!ok) {
    std::remove(tmp.c_str());
    throw OutputError("cannot write " + tmp + " (" + std::strerror(write_errno ? write_errno : ENOSPC) + "; disk full?)");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string err = std::strerror(errno);
    std::remove(tmp.c_str());
    throw OutputError("cannot rename " + tmp + " to " + path + ": " + err);
  }
}

namespace {
void append_double(std::string& s, double v) {
  char buf[32];
  auto r = std::to_chars(buf, buf + sizeof(buf), v, std::chars_format::general, 9);
  s.append(buf, r.ptr);
}
void append_int(std::string& s, long long v) {
  char buf[24];
  auto r = std::to_chars(buf, buf + sizeof(buf), v);
  s.append(buf, r.ptr);
}
}  // namespace

namespace {
void append_exact(std::string& s, double v) {
  char buf[32];
  auto r = std::to_chars(buf, buf + sizeof(buf), v);  // shortest representation that round-trips
  s.append(buf, r.ptr);
}
}  // namespace

std::string obj_text(const Mesh& mesh, std::span<const double> x, const std::string& comment, const ObjOptions& o) {
  const bool uvs = o.uvs && mesh.uvs.size() * 3 == x.size() * 2 && !x.empty();
  const bool normals = o.normals;
  auto num = o.lossless ? append_exact : append_double;
  std::string s;
  s.reserve(x.size() * (o.lossless ? 22 : 14) * (normals ? 2 : 1) + mesh.triangles.size() * (uvs || normals ? 16 : 8) + 128);
  s += "# Loom frame";
  if (!comment.empty()) s += ": " + comment;
  s += '\n';
  for (std::size_t i = 0; i + 2 < x.size(); i += 3) {
    s += "v ";
    num(s, x[i]);
    s += ' ';
    num(s, x[i + 1]);
    s += ' ';
    num(s, x[i + 2]);
    s += '\n';
  }
  // Texture coordinates: one vt per vertex (vt i is vertex i's uv), then, for a mesh with UV
  // seams (per-corner uvs that differ from their vertex's), one more vt per distinct such uv,
  // in the order of first use; each face corner names its own. A mesh without seams writes the
  // per-vertex list alone, with f v/v.
  std::vector<long long> corner_vt;  // 1-based vt of each corner, when some corner differs
  if (uvs) {
    for (std::size_t i = 0; i + 1 < mesh.uvs.size(); i += 2) {
      s += "vt ";
      num(s, mesh.uvs[i]);
      s += ' ';
      num(s, mesh.uvs[i + 1]);
      s += '\n';
    }
    if (mesh.corner_uvs.size() == 2 * mesh.triangles.size()) {
      std::map<std::pair<double, double>, long long> extra;
      long long next = static_cast<long long>(mesh.uvs.size() / 2) + 1;
      for (std::size_t c = 0; c < mesh.triangles.size(); ++c) {
        const double* w = &mesh.corner_uvs[2 * c];
        const double* vw = &mesh.uvs[2 * static_cast<std::size_t>(mesh.triangles[c])];
        if (w[0] == vw[0] && w[1] == vw[1]) continue;
        if (corner_vt.empty()) {
          corner_vt.resize(mesh.triangles.size());
          for (std::size_t k = 0; k < corner_vt.size(); ++k) corner_vt[k] = mesh.triangles[k] + 1;
        }
        const auto [it, fresh] = extra.emplace(std::make_pair(w[0], w[1]), next);
        if (fresh) {
          ++next;
          s += "vt ";
          num(s, w[0]);
          s += ' ';
          num(s, w[1]);
          s += '\n';
        }
        corner_vt[c] = it->second;
      }
    }
  }
  if (normals) {
    // Area-weighted vertex normals: the sum of the (unnormalised) cross products of the
    // triangles around a vertex, normalised.
    std::vector<double> nrm(x.size(), 0.0);
    for (std::size_t t = 0; t + 2 < mesh.triangles.size(); t += 3) {
      const std::size_t a = 3 * static_cast<std::size_t>(mesh.triangles[t]), b = 3 * static_cast<std::size_t>(mesh.triangles[t + 1]),
                        c = 3 * static_cast<std::size_t>(mesh.triangles[t + 2]);
      const double e1[3] = {x[b] - x[a], x[b + 1] - x[a + 1], x[b + 2] - x[a + 2]};
      const double e2[3] = {x[c] - x[a], x[c + 1] - x[a + 1], x[c + 2] - x[a + 2]};
      const double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
      for (std::size_t v : {a, b, c})
        for (int k = 0; k < 3; ++k) nrm[v + k] += n[k];
    }
    for (std::size_t i = 0; i + 2 < nrm.size(); i += 3) {
      const double len = std::sqrt(nrm[i] * nrm[i] + nrm[i + 1] * nrm[i + 1] + nrm[i + 2] * nrm[i + 2]);
      const double inv = len > 0 ? 1.0 / len : 0.0;
      s += "vn ";
      append_double(s, nrm[i] * inv);
      s += ' ';
      append_double(s, nrm[i + 1] * inv);
      s += ' ';
      append_double(s, nrm[i + 2] * inv);
      s += '\n';
    }
  }
  for (std::size_t t = 0; t + 2 < mesh.triangles.size(); t += 3) {
    s += 'f';
    for (int k = 0; k < 3; ++k) {
      const long long idx = mesh.triangles[t + k] + 1;
      s += ' ';
      append_int(s, idx);
      if (uvs || normals) {
        s += '/';
        if (uvs) append_int(s, corner_vt.empty() ? idx : corner_vt[t + k]);
        if (normals) {
          s += '/';
          append_int(s, idx);
        }
      }
    }
    s += '\n';
  }
  return s;
}

PointCacheWriter::PointCacheWriter(const std::string& path, int num_points, float start_frame, float sample_rate)
    : path_(path), points_(num_points), buf_(3 * static_cast<std::size_t>(num_points)) {
  f_ = std::fopen(path.c_str(), "wb");
  if (!f_) throw std::runtime_error("cannot create " + path + ": " + std::strerror(errno));
  char header[32] = {0};
  std::memcpy(header, "POINTCACHE2", 11);  // 12 bytes with the terminating zero
  const std::int32_t version = 1, points = num_points, samples = 0;
  std::memcpy(header + 12, &version, 4);
  std::memcpy(header + 16, &points, 4);
  std::memcpy(header + 20, &start_frame, 4);
  std::memcpy(header + 24, &sample_rate, 4);
  std::memcpy(header + 28, &samples, 4);
  if (std::fwrite(header, 1, 32, f_) != 32 || std::fflush(f_) != 0)
    throw OutputError("cannot write " + path + " (" + std::strerror(errno) + "; disk full?)");
}

PointCacheWriter::PointCacheWriter(const std::string& path, int num_points, int keep_samples)
    : path_(path), points_(num_points), buf_(3 * static_cast<std::size_t>(num_points)) {
  f_ = std::fopen(path.c_str(), "r+b");
  if (!f_)
    throw InputError(path + ": cannot continue the point cache (" + std::strerror(errno) +
                     "). Fix: rerun the scene with --overwrite instead of --resume.");
  char header[32] = {0};
  std::int32_t points = 0, samples = 0;
  const bool read = std::fread(header, 1, 32, f_) == 32;
  std::memcpy(&points, header + 16, 4);
  std::memcpy(&samples, header + 28, 4);
  if (!read || std::memcmp(header, "POINTCACHE2", 12) != 0 || points != num_points || samples < keep_samples ||
      keep_samples < 0) {
    std::fclose(f_);
    f_ = nullptr;
    throw InputError(path + ": does not match the run being resumed (" + std::to_string(points) + " points, " +
                     std::to_string(samples) + " samples; expected " + std::to_string(num_points) + " points and at least " +
                     std::to_string(keep_samples) + " samples). Fix: rerun the scene with --overwrite instead of --resume.");
  }
  samples_ = keep_samples;
  const std::int32_t count = samples_;
  const long end = 32L + static_cast<long>(samples_) * static_cast<long>(buf_.size()) * 4L;
  if (std::fseek(f_, 28, SEEK_SET) != 0 || std::fwrite(&count, 4, 1, f_) != 1 || std::fflush(f_) != 0 ||
      ::ftruncate(::fileno(f_), end) != 0)
    throw OutputError("cannot write " + path + " (" + std::strerror(errno) + "; disk full?)");
}

PointCacheWriter::~PointCacheWriter() {
  if (f_) std::fclose(f_);
}

void PointCacheWriter::append(std::span<const double> x) {
  if (x.size() != buf_.size())
    throw std::runtime_error(path_ + ": a sample has " + std::to_string(x.size() / 3) + " points, the cache " +
                             std::to_string(points_));
  for (std::size_t i = 0; i < x.size(); ++i) buf_[i] = static_cast<float>(x[i]);
  const std::int32_t next = samples_ + 1;
  const long offset = 32L + static_cast<long>(samples_) * static_cast<long>(buf_.size()) * 4L;
  bool ok = std::fseek(f_, offset, SEEK_SET) == 0 && std::fwrite(buf_.data(), 4, buf_.size(), f_) == buf_.size() &&
            std::fflush(f_) == 0;
  // Only now that the sample is on disk does the header count it.
  ok = ok && std::fseek(f_, 28, SEEK_SET) == 0 && std::fwrite(&next, 4, 1, f_) == 1 && std::fflush(f_) == 0;
  if (!ok) throw OutputError("cannot write " + path_ + " (" + std::strerror(errno) + "; disk full?)");
  samples_ = next;
}

void prepare_output_dir(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir))
    throw InputError("cannot create output folder '" + dir + "': " + (ec ? ec.message() : "not a folder") +
                     ". Fix: choose a writable folder with --out DIR (or output.dir in the scene).");
  const std::string probe = (fs::path(dir) / (".loom_write_test." + std::to_string(::getpid()))).string();
  FILE* f = std::fopen(probe.c_str(), "wb");
  if (!f)
    throw InputError("output folder '" + dir + "' is not writable (" + std::strerror(errno) +
                     "). Fix: choose a writable folder with --out DIR.");
  std::fclose(f);
  std::remove(probe.c_str());
}

OutputLock::OutputLock(const std::string& dir) {
  const std::string path = (fs::path(dir) / ".loom.lock").string();
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0)
    throw InputError("cannot create " + path + ": " + std::strerror(errno) + ". Fix: choose a writable --out folder.");
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    char buf[32] = {0};
    const ssize_t n = ::pread(fd_, buf, sizeof(buf) - 1, 0);
    const std::string pid = n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : std::string("?");
    ::close(fd_);
    fd_ = -1;
    throw InputError("output folder '" + dir + "' is in use by another loom run (pid " + pid +
                     "). Fix: wait for it to finish, or write this run elsewhere with --out DIR.");
  }
  const std::string me = std::to_string(::getpid());
  if (::ftruncate(fd_, 0) == 0) {
    [[maybe_unused]] const ssize_t w = ::pwrite(fd_, me.data(), me.size(), 0);
  }
}

OutputLock::~OutputLock() {
  if (fd_ >= 0) ::close(fd_);  // closing releases the flock; the file stays (harmless, reused)
}

int remove_stale_temporaries(const std::string& dir) {
  int removed = 0;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    const auto pos = name.rfind(".tmp.");
    if (pos == std::string::npos || pos + 5 >= name.size()) continue;
    if (!std::all_of(name.begin() + static_cast<std::ptrdiff_t>(pos) + 5, name.end(), [](char c) { return c >= '0' && c <= '9'; }))
      continue;
    std::error_code rm;
    if (fs::remove(e.path(), rm)) ++removed;
  }
  return removed;
}

std::vector<std::string> run_files_in(const std::string& dir) {
  std::vector<std::string> out;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    const bool frame = name.rfind("frame_", 0) == 0 && name.size() > 4 && name.compare(name.size() - 4, 4, ".obj") == 0;
    const bool vtu = name.rfind("frame_", 0) == 0 && name.size() > 4 && name.compare(name.size() - 4, 4, ".vtu") == 0;
    if (frame || vtu || name == "stats.csv" || name == "run.pc2" || name == "rest.obj" || name == "scene.yaml" ||
        name == "velocity.pc2" || name == "run.pvd" || name == "restart.bin")
      out.push_back(e.path().string());
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace loom
