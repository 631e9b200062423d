#include "geometry/mesh_io.h"
#include "geometry/mesh_file_check.h"

#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <assimp/Importer.hpp>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <system_error>
#include <tuple>

#include "util/check.h"
#include "util/file.h"
#include "util/string_util.h"

namespace arpos {
namespace {

// Collects the meshes below `node` (with accumulated transforms), filtered by
// group name when `only_group` is set: a node or mesh of that name selects
// itself and everything below it.
void CollectMeshes(const aiScene* scene, const aiNode* node, const aiMatrix4x4& parent,
                   const std::string& only_group, bool selected,
                   std::vector<std::pair<const aiMesh*, aiMatrix4x4>>* out) {
  const aiMatrix4x4 transform = parent * node->mTransformation;
  const bool node_selected =
      selected || only_group.empty() || only_group == node->mName.C_Str();
  for (unsigned i = 0; i < node->mNumMeshes; ++i) {
    const aiMesh* mesh = scene->mMeshes[node->mMeshes[i]];
    if (node_selected || only_group == mesh->mName.C_Str()) out->emplace_back(mesh, transform);
  }
  for (unsigned i = 0; i < node->mNumChildren; ++i) {
    CollectMeshes(scene, node->mChildren[i], transform, only_group, node_selected, out);
  }
}

void AppendLE(std::string* out, const void* data, size_t n) {
  // PLY binary_little_endian: copy bytes in little-endian order regardless of host.
  const auto* bytes = static_cast<const unsigned char*>(data);
  if constexpr (__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__) {
    out->append(reinterpret_cast<const char*>(bytes), n);
  } else {
    for (size_t i = 0; i < n; ++i) out->push_back(static_cast<char>(bytes[n - 1 - i]));
  }
}

// A PLY file read by ReadPlyFile (mesh_file_check.h; assimp misreads some
// binary ones), built as the assimp path builds a mesh: polygons as fans,
// faces of fewer than three vertices and degenerate triangles dropped,
// vertices no face uses left out, bit-identical positions merged unless
// normals are kept.
TriangleMesh MeshFromPly(const std::filesystem::path& path, const MeshLoadOptions& options) {
  if (!options.only_group.empty()) {
    ARPOS_INPUT_ERROR(path.string() << ": no group or mesh named '" << options.only_group
                                    << "' (a PLY file holds one unnamed mesh)");
  }
  const PlyContents ply = ReadPlyFile(path);
  const bool have_normals = options.keep_normals && !ply.normals.empty();
  const float scale = static_cast<float>(options.units_scale);
  TriangleMesh result;
  // Vertices in the file's order, those no face uses left out.
  std::vector<int> index_of(ply.positions.size(), -1);
  for (size_t f = 0, start = 0; f < ply.face_sizes.size(); start += ply.face_sizes[f++]) {
    if (ply.face_sizes[f] < 3) continue;
    for (size_t k = 0; k < ply.face_sizes[f]; ++k)
      index_of[static_cast<size_t>(ply.face_indices[start + k])] = 0;
  }
  std::map<std::tuple<float, float, float>, int> merged;
  for (size_t v = 0; v < ply.positions.size(); ++v) {
    if (index_of[v] < 0) continue;
    const Eigen::Vector3f position = ply.positions[v].cast<float>() * scale;
    if (!position.allFinite()) {
      const Eigen::Vector3d& raw = ply.positions[v];
      ARPOS_INPUT_ERROR(path.string()
                        << ": vertex " << v << " is (" << raw.x() << ", " << raw.y() << ", "
                        << raw.z() << ")" << (scale != 1.0f ? " in file units" : "")
                        << ": coordinates must be finite numbers");
    }
    if (options.merge_identical_positions && !have_normals) {
      const auto [it, inserted] =
          merged.emplace(std::make_tuple(position.x(), position.y(), position.z()),
                         static_cast<int>(result.vertices.size()));
      if (inserted) result.vertices.push_back(position);
      index_of[v] = it->second;
    } else {
      index_of[v] = static_cast<int>(result.vertices.size());
      result.vertices.push_back(position);
      if (have_normals) result.vertex_normals.push_back(ply.normals[v].cast<float>().normalized());
    }
  }
  auto vertex = [&](size_t i) { return index_of[static_cast<size_t>(ply.face_indices[i])]; };
  for (size_t f = 0, start = 0; f < ply.face_sizes.size(); start += ply.face_sizes[f++]) {
    for (size_t k = 1; k + 1 < ply.face_sizes[f]; ++k) {
      const Eigen::Vector3i tri(vertex(start), vertex(start + k), vertex(start + k + 1));
      if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) continue;
      result.faces.push_back(tri);
    }
  }
  if (result.faces.empty()) ARPOS_INPUT_ERROR(path.string() << ": mesh has no triangles");
  return result;
}

}  // namespace

TriangleMesh LoadTriangleMesh(const std::filesystem::path& path, const MeshLoadOptions& options) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    ARPOS_INPUT_ERROR(path.string() << ": mesh file does not exist or is not a regular file");
  }
  if (!(options.units_scale > 0)) {
    ARPOS_INPUT_ERROR(path.string() << ": units scale must be positive, got "
                                    << options.units_scale);
  }
  if (ToLower(path.extension().string()) == ".ply") return MeshFromPly(path, options);
  // assimp 5.2 crashes or invents faces on some malformed files: refuse them first.
  CheckMeshFileStructure(path);
  Assimp::Importer importer;
  // Drop everything we do not use so assimp does less work.
  int removed = aiComponent_COLORS | aiComponent_TEXCOORDS | aiComponent_ANIMATIONS |
                aiComponent_TANGENTS_AND_BITANGENTS | aiComponent_BONEWEIGHTS;
  if (!options.keep_normals) removed |= aiComponent_NORMALS;
  importer.SetPropertyInteger(AI_CONFIG_PP_RVC_FLAGS, removed);
  const unsigned flags =
      aiProcess_RemoveComponent | aiProcess_Triangulate | aiProcess_JoinIdenticalVertices;
  const aiScene* scene = nullptr;
  {
    std::ifstream in(path, std::ios::binary);
    std::string head(8, '\0');
    in.read(head.data(), static_cast<std::streamsize>(head.size()));
    head.resize(static_cast<size_t>(std::max<std::streamsize>(0, in.gcount())));
    if (const size_t start = TextMeshStart(head); start > 0) {
      // assimp reads a byte-order mark into the first line (an OBJ's first
      // vertex lost, "vertex index out of range"): read without it.
      std::ostringstream buffer;
      buffer << in.rdbuf();
      const std::string data = head.substr(start) + buffer.str();
      const std::string hint = ToLower(path.extension().string()).substr(1);
      scene = importer.ReadFileFromMemory(data.data(), data.size(), flags, hint.c_str());
    } else {
      scene = importer.ReadFile(path.string(), flags);
    }
  }
  if (scene == nullptr || scene->mRootNode == nullptr) {
    ARPOS_INPUT_ERROR(path.string() << ": cannot read mesh: " << importer.GetErrorString());
  }
  std::vector<std::pair<const aiMesh*, aiMatrix4x4>> meshes;
  CollectMeshes(scene, scene->mRootNode, aiMatrix4x4(), options.only_group, false, &meshes);
  if (!options.only_group.empty() && meshes.empty()) {
    ARPOS_INPUT_ERROR(path.string() << ": no group or mesh named '" << options.only_group << "'");
  }

  TriangleMesh result;
  const float scale = static_cast<float>(options.units_scale);
  // Position -> merged index (exact bit equality of the scaled float triple).
  std::map<std::tuple<float, float, float>, int> merged;
  bool have_normals = options.keep_normals;
  for (const auto& [mesh, transform] : meshes) {
    if (!mesh->HasNormals()) have_normals = false;
  }
  for (const auto& [mesh, transform] : meshes) {
    aiMatrix3x3 normal_transform(transform);
    normal_transform.Inverse().Transpose();
    std::vector<int> index_of(mesh->mNumVertices);
    for (unsigned v = 0; v < mesh->mNumVertices; ++v) {
      const aiVector3D p = transform * mesh->mVertices[v];
      const Eigen::Vector3f position(p.x * scale, p.y * scale, p.z * scale);
      if (!position.allFinite()) {
        // Before merging: a NaN compares equal to every position and would
        // silently become another vertex.
        const aiVector3D& raw = mesh->mVertices[v];
        ARPOS_INPUT_ERROR(path.string() << ": vertex " << v << " is (" << raw.x << ", " << raw.y << ", "
                                        << raw.z << ")" << (scale != 1.0f ? " in file units" : "")
                                        << ": coordinates must be finite numbers");
      }
      if (options.merge_identical_positions && !have_normals) {
        const auto key = std::make_tuple(position.x(), position.y(), position.z());
        const auto [it, inserted] = merged.emplace(key, static_cast<int>(result.vertices.size()));
        if (inserted) result.vertices.push_back(position);
        index_of[v] = it->second;
      } else {
        index_of[v] = static_cast<int>(result.vertices.size());
        result.vertices.push_back(position);
        if (have_normals) {
          aiVector3D n = normal_transform * mesh->mNormals[v];
          n.Normalize();
          result.vertex_normals.emplace_back(n.x, n.y, n.z);
        }
      }
    }
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices != 3) continue;  // points and lines
      const Eigen::Vector3i tri(index_of[face.mIndices[0]], index_of[face.mIndices[1]],
                                index_of[face.mIndices[2]]);
      if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) continue;
      result.faces.push_back(tri);
    }
  }
  if (result.faces.empty()) {
    ARPOS_INPUT_ERROR(path.string() << ": mesh has no triangles"
                                    << (options.only_group.empty()
                                            ? std::string()
                                            : " in group '" + options.only_group + "'"));
  }
  return result;
}

TriangleMesh LoadTriangleMesh(const std::filesystem::path& path, double units_scale) {
  MeshLoadOptions options;
  options.units_scale = units_scale;
  return LoadTriangleMesh(path, options);
}

void SaveTriangleMeshPly(const TriangleMesh& mesh, const std::filesystem::path& path,
                         const std::string& comment) {
  ARPOS_CHECK(!mesh.vertices.empty(), "refusing to write an empty mesh to " << path.string());
  std::vector<Eigen::Vector3f> normals = mesh.vertex_normals;
  if (normals.size() != mesh.vertices.size()) {
    TriangleMesh copy;
    copy.vertices = mesh.vertices;
    copy.faces = mesh.faces;
    copy.ComputeVertexNormals();
    normals = std::move(copy.vertex_normals);
  }
  std::string out;
  out += "ply\nformat binary_little_endian 1.0\n";
  if (!comment.empty()) {
    size_t start = 0;
    while (start <= comment.size()) {
      const size_t end = comment.find('\n', start);
      out += "comment " + comment.substr(start, end - start) + "\n";
      if (end == std::string::npos) break;
      start = end + 1;
    }
  }
  out += "element vertex " + std::to_string(mesh.vertices.size()) + "\n";
  out += "property float x\nproperty float y\nproperty float z\n";
  out += "property float nx\nproperty float ny\nproperty float nz\n";
  out += "element face " + std::to_string(mesh.faces.size()) + "\n";
  out += "property list uchar int vertex_indices\nend_header\n";
  out.reserve(out.size() + mesh.vertices.size() * 24 + mesh.faces.size() * 13);
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    for (int k = 0; k < 3; ++k) AppendLE(&out, &mesh.vertices[i][k], 4);
    for (int k = 0; k < 3; ++k) AppendLE(&out, &normals[i][k], 4);
  }
  const int num_vertices = static_cast<int>(mesh.vertices.size());
  for (const auto& f : mesh.faces) {
    ARPOS_CHECK(f.minCoeff() >= 0 && f.maxCoeff() < num_vertices,
                "face index out of range writing " << path.string());
    out.push_back(3);
    for (int k = 0; k < 3; ++k) {
      const int32_t index = f[k];
      AppendLE(&out, &index, 4);
    }
  }
  WriteFileAtomic(path, out);
}

}  // namespace arpos
