#include "loom/restart.hpp"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "loom/common.hpp"
#include "loom/output.hpp"

namespace fs = std::filesystem;

namespace loom {

namespace {

constexpr char kMagic[8] = {'L', 'O', 'O', 'M', 'R', 'S', 'T', '1'};

// 64-bit FNV-1a (offset basis 0xcbf29ce484222325). Builds before 2026-11-29 wrote the hash
// with the offset basis 1469598103934665603 (a digit short); read_restart accepts both.
constexpr std::uint64_t kFnvBasis = 14695981039346656037ULL;
constexpr std::uint64_t kFnvBasisOld = 1469598103934665603ULL;

std::uint64_t fnv1a(const char* p, std::size_t n, std::uint64_t basis = kFnvBasis) {
  std::uint64_t h = basis;
  for (std::size_t i = 0; i < n; ++i) {
    h ^= static_cast<unsigned char>(p[i]);
    h *= 1099511628211ULL;
  }
  return h;
}

template <class T>
void put(std::string& s, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  s.append(b, sizeof(T));
}

void put_doubles(std::string& s, const std::vector<double>& a) {
  if (!a.empty()) s.append(reinterpret_cast<const char*>(a.data()), a.size() * sizeof(double));
}

}  // namespace

std::string restart_bytes(const RestartData& r) {
  std::string s(kMagic, 8);
  put<std::int32_t>(s, r.frame);
  put<std::int32_t>(s, r.frames);
  put<std::int64_t>(s, r.step);
  put<double>(s, r.time);
  put<std::int64_t>(s, r.force_evaluations);
  put<std::int64_t>(s, r.linear_iterations);
  put<std::int64_t>(s, static_cast<std::int64_t>(r.x.size() / 3));
  put_doubles(s, r.x);
  put_doubles(s, r.v);
  put<std::int64_t>(s, static_cast<std::int64_t>(r.integrator_state.size()));
  put_doubles(s, r.integrator_state);
  put<std::uint64_t>(s, fnv1a(s.data(), s.size()));
  return s;
}

void write_restart(const std::string& dir, const RestartData& r) {
  write_file_atomic((fs::path(dir) / "restart.bin").string(), restart_bytes(r));
}

RestartData read_restart(const std::string& dir) {
  const std::string path = (fs::path(dir) / "restart.bin").string();
  std::ifstream in(path, std::ios::binary);
  if (!in)
    throw InputError(path + ": no restart point. Fix: --resume needs the folder of a run made by this Loom version "
                     "with output.restart on (it writes restart.bin from frame 0 on); start the run again without --resume.");
  const std::string s((std::istreambuf_iterator<char>(in)), {});
  std::size_t pos = 0;
  auto damaged = [&](const std::string& why) {
    return InputError(path + ": damaged restart point (" + why +
                      "). Fix: rerun the scene with --overwrite; the frames already written stay readable.");
  };
  auto get = [&](auto& v) {
    if (pos + sizeof(v) > s.size()) throw damaged("truncated at byte " + std::to_string(pos));
    std::memcpy(&v, s.data() + pos, sizeof(v));
    pos += sizeof(v);
  };
  auto get_doubles = [&](std::vector<double>& a, std::int64_t count) {
    if (count < 0 || static_cast<std::uint64_t>(count) > (s.size() - pos) / sizeof(double))
      throw damaged("truncated at byte " + std::to_string(pos));
    a.resize(static_cast<std::size_t>(count));
    if (!a.empty()) std::memcpy(a.data(), s.data() + pos, a.size() * sizeof(double));
    pos += a.size() * sizeof(double);
  };
  if (s.size() < 8 + 8 || std::memcmp(s.data(), kMagic, 8) != 0) throw damaged("not a Loom restart file");
  std::uint64_t stored = 0;
  std::memcpy(&stored, s.data() + s.size() - 8, 8);
  if (stored != fnv1a(s.data(), s.size() - 8) && stored != fnv1a(s.data(), s.size() - 8, kFnvBasisOld))
    throw damaged("checksum mismatch");
  pos = 8;
  RestartData r;
  std::int32_t frame = 0, frames = 0;
  std::int64_t step = 0, fe = 0, li = 0, n = 0, k = 0;
  get(frame);
  get(frames);
  get(step);
  get(r.time);
  get(fe);
  get(li);
  get(n);
  if (n < 0 || static_cast<std::uint64_t>(n) > s.size() / 48) throw damaged("bad vertex count");
  r.frame = frame;
  r.frames = frames;
  r.step = step;
  r.force_evaluations = fe;
  r.linear_iterations = li;
  get_doubles(r.x, 3 * n);
  get_doubles(r.v, 3 * n);
  get(k);
  get_doubles(r.integrator_state, k);
  if (pos + 8 != s.size()) throw damaged("unexpected length");
  return r;
}

}  // namespace loom
