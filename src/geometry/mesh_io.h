#pragma once
/// Triangle-mesh files: loading PLY with the project's reader
/// (mesh_file_check.h: assimp 5.2.5 misreads binary PLY whose data starts
/// with a whitespace byte) and everything else through assimp (STL, OBJ, OFF
/// and the other formats it reads); writing binary PLY.
///
/// Units: files store whatever unit their author chose; `units_scale` converts
/// to metres on load (1 for metres, 0.001 for millimetres, 0.1 for MakeHuman
/// decimetres). No axis conversion is done: coordinates keep the file's frame.

#include <filesystem>
#include <string>

#include "geometry/triangle_mesh.h"

namespace arpos {

struct MeshLoadOptions {
  /// Multiplies every coordinate (file units -> metres).
  double units_scale = 1.0;
  /// If not empty, keep only the meshes whose assimp node or mesh name equals
  /// this (an OBJ `g`/`o` group such as "body"); InputError if none matches.
  std::string only_group;
  /// Merge vertices with bit-identical positions (assimp keeps vertices apart
  /// where texture coordinates or normals differ; geometry does not need that).
  bool merge_identical_positions = true;
  /// Keep per-vertex normals from the file if it has them (else none; call
  /// TriangleMesh::ComputeVertexNormals()).
  bool keep_normals = false;
};

/// Loads a mesh with aiProcess_Triangulate | aiProcess_JoinIdenticalVertices
/// (PLY: read directly, polygons as fans, vertices no face uses left out).
/// Every mesh of the scene (or of the selected group) is concatenated in
/// scene-graph order with its node transforms applied. Faces keep the file's
/// winding. Throws InputError naming the file if it is missing, unreadable,
/// corrupt (mesh_file_check.h), has no triangles, a vertex with a NaN or
/// infinite coordinate (naming the vertex and its value), or the requested
/// group is absent.
TriangleMesh LoadTriangleMesh(const std::filesystem::path& path,
                              const MeshLoadOptions& options);
/// Same with only a unit scale.
TriangleMesh LoadTriangleMesh(const std::filesystem::path& path, double units_scale = 1.0);

/// Writes binary little-endian PLY (float x y z, float nx ny nz, uchar-count
/// int vertex_indices) atomically (WriteFileAtomic). Normals are written if
/// the mesh has one per vertex, else computed from the faces on a copy.
/// `comment` lines (no newlines) go into the header. Throws arpos::Error if the
/// file cannot be written, InputError-free otherwise.
void SaveTriangleMeshPly(const TriangleMesh& mesh, const std::filesystem::path& path,
                         const std::string& comment = "");

}  // namespace arpos
