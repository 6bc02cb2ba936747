// Output writers: OBJ frames (written atomically) and the per-frame stats CSV.
#pragma once

#include "loom/launcher.hpp"

#include <cstdio>
#include <span>
#include <string>
#include <vector>

#include "loom/mesh.hpp"

namespace loom {

/// Write `text` to `path` atomically: a temporary file in the same folder, flushed,
/// then renamed over the target. Throws std::runtime_error with the path on failure.
void write_file_atomic(const std::string& path, const std::string& text);

/// What an OBJ frame carries besides positions and triangles.
struct ObjOptions {
  bool uvs = false;        ///< `vt` lines and f v/vt (only when the mesh has UVs)
  bool normals = false;    ///< `vn` lines (area-weighted vertex normals of the frame) and f v//vn
  bool lossless = false;   ///< shortest round-trip decimal of every double (else 9 significant digits)
};

/// OBJ text of the mesh's triangles at positions x (3n), with a comment header.
std::string obj_text(const Mesh& mesh, std::span<const double> x, const std::string& comment = "",
                     const ObjOptions& options = {});

/// A PC2 point cache (the layout Blender's Mesh Cache modifier, Houdini, Maya and 3ds Max
/// read): a 32-byte header "POINTCACHE2\0", int32 version 1, int32 point count, float32 start
/// frame, float32 sample rate, int32 sample count; then per sample the points' float32 x y z,
/// little endian. The sample count in the header is rewritten after every append, so a file
/// of a killed run is complete up to its last whole sample.
class PointCacheWriter {
 public:
  PointCacheWriter(const std::string& path, int num_points, float start_frame = 0.0f, float sample_rate = 1.0f);
  /// Continue an existing cache (loom run --resume): keep its first keep_samples samples and
  /// append after them. Throws InputError when the file is missing, has another point count or
  /// fewer samples.
  PointCacheWriter(const std::string& path, int num_points, int keep_samples);
  ~PointCacheWriter();
  PointCacheWriter(const PointCacheWriter&) = delete;
  PointCacheWriter& operator=(const PointCacheWriter&) = delete;
  /// Append one sample (x: 3 * num_points doubles, stored as float32). Throws on write errors.
  void append(std::span<const double> x);
  int samples() const { return samples_; }

 private:
  std::string path_;
  FILE* f_ = nullptr;
  int points_ = 0, samples_ = 0;
  std::vector<float> buf_;
};

/// Make sure `dir` exists and is writable; throws InputError naming the folder and the fix.
void prepare_output_dir(const std::string& dir);

/// Exclusive claim on an output folder for one run: an flock on DIR/.loom.lock, released when
/// the object is destroyed or the process dies (kill -9 included). A second run into the same
/// folder gets an InputError naming the folder and the fix.
class OutputLock {
 public:
  explicit OutputLock(const std::string& dir);
  ~OutputLock();
  OutputLock(const OutputLock&) = delete;
  OutputLock& operator=(const OutputLock&) = delete;

 private:
  int fd_ = -1;
};

/// Remove temporary files (NAME.tmp.PID) that a killed run left in dir; returns how many.
int remove_stale_temporaries(const std::string& dir);

/// Files a run writes that are present in dir (frame_*.obj, frame_*.vtu, stats.csv, run.pc2,
/// velocity.pc2, run.pvd, rest.obj, restart.bin, scene.yaml), sorted.
std::vector<std::string> run_files_in(const std::string& dir);

/// is_output_rank(): false on MPI ranks other than 0, which write nothing (loom/launcher.hpp).

}  // namespace loom
