#include "loom/output.hpp"

#include <unistd.h>

#include <charconv>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "loom/common.hpp"

namespace fs = std::filesystem;

namespace loom {

void write_file_atomic(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) throw std::runtime_error("cannot create " + tmp + ": " + std::strerror(errno));
  const std::size_t n = std::fwrite(text.data(), 1, text.size(), f);
  const bool ok = n == text.size() && std::fflush(f) == 0;
  std::fclose(f);
  if (!ok) {
    std::remove(tmp.c_str());
    throw std::runtime_error("cannot write " + tmp + " (disk full?)");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string err = std::strerror(errno);
    std::remove(tmp.c_str());
    throw std::runtime_error("cannot rename " + tmp + " to " + path + ": " + err);
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

std::string obj_text(const Mesh& mesh, std::span<const double> x, const std::string& comment) {
  std::string s;
  s.reserve(x.size() * 14 + mesh.triangles.size() * 8 + 128);
  s += "# Loom frame";
  if (!comment.empty()) s += ": " + comment;
  s += '\n';
  for (std::size_t i = 0; i + 2 < x.size(); i += 3) {
    s += "v ";
    append_double(s, x[i]);
    s += ' ';
    append_double(s, x[i + 1]);
    s += ' ';
    append_double(s, x[i + 2]);
    s += '\n';
  }
  for (std::size_t t = 0; t + 2 < mesh.triangles.size(); t += 3) {
    s += "f ";
    append_int(s, mesh.triangles[t] + 1);
    s += ' ';
    append_int(s, mesh.triangles[t + 1] + 1);
    s += ' ';
    append_int(s, mesh.triangles[t + 2] + 1);
    s += '\n';
  }
  return s;
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

bool is_output_rank() {
  for (const char* var : {"OMPI_COMM_WORLD_RANK", "PMI_RANK", "PMIX_RANK"}) {
    if (const char* v = std::getenv(var)) return std::atoi(v) == 0;
  }
  return true;
}

}  // namespace loom
