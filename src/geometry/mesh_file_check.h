#pragma once
/// Structural validation of PLY, OFF and binary STL files before assimp
/// reads them.
///
/// Why: assimp 5.2.5 (Debian 12) crashes or returns garbage on hostile
/// files, measured: a binary PLY cut short segfaults inside
/// aiProcess_JoinIdenticalVertices; an OFF file with fewer faces than its
/// header declares aborts the process; an ASCII PLY with a missing face, or an
/// OFF face index beyond the vertex count, is accepted with invented faces.
/// This check walks the file against its own header (counts, sizes, face
/// indices, finite coordinates) without building a mesh, so such files are
/// refused with a clear message instead. Other extensions pass unchecked (assimp's OBJ and STL
/// readers refuse those cases themselves).

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace arpos {

/// Throws InputError naming `path` if a .ply, .off or binary .stl file is
/// malformed: unknown header, counts larger than the file can hold, data
/// shorter than declared, face indices out of range, non-numbers, NaN or
/// infinite values. Returns silently for a sound file or another extension.
void CheckMeshFileStructure(const std::filesystem::path& path);

/// Where a text mesh file's content starts: 3 after a UTF-8 byte-order mark
/// followed by a text format's first keyword (what Windows tools write
/// first; readers take it for part of the first line), else 0.
size_t TextMeshStart(const std::string& data);

/// What a PLY file holds, in file units.
struct PlyContents {
  std::vector<Eigen::Vector3d> positions;
  /// Empty unless the vertices have nx, ny and nz.
  std::vector<Eigen::Vector3d> normals;
  /// Each face's vertex indices (its 'vertex_indices' or 'vertex_index'
  /// list, else its first integer list), one face after the other; face f
  /// has face_sizes[f] of them. Empty without a face element.
  std::vector<int64_t> face_indices;
  std::vector<uint32_t> face_sizes;
};

/// Reads a PLY file (ASCII or binary, either byte order) with the checks of
/// CheckMeshFileStructure; InputError naming the file otherwise. Why not
/// assimp: assimp 5.2.5 skips whitespace after `end_header`, so a binary
/// PLY whose first data byte is 0x09-0x0d or 0x20 is misread (measured: a
/// simulated reference model starting with 0x0a gave 337 faces with
/// garbage indices, and assimp segfaulted in its post-processing).
PlyContents ReadPlyFile(const std::filesystem::path& path);

}  // namespace arpos
