// Output writers: OBJ frames (written atomically) and the per-frame stats CSV.
#pragma once

#include <cstdio>
#include <span>
#include <string>

#include "loom/mesh.hpp"

namespace loom {

/// Write `text` to `path` atomically: a temporary file in the same folder, flushed,
/// then renamed over the target. Throws std::runtime_error with the path on failure.
void write_file_atomic(const std::string& path, const std::string& text);

/// OBJ text of the mesh's triangles at positions x (3n), with a comment header.
std::string obj_text(const Mesh& mesh, std::span<const double> x, const std::string& comment = "");

/// Make sure `dir` exists and is writable; throws InputError naming the folder and the fix.
void prepare_output_dir(const std::string& dir);

/// False on MPI ranks other than 0 (OMPI_COMM_WORLD_RANK / PMI_RANK), which write nothing.
bool is_output_rank();

}  // namespace loom
