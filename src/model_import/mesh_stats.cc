#include "model_import/mesh_stats.h"

#include <numeric>
#include <unordered_map>
#include <vector>

namespace arpos {
namespace {

int FindRoot(std::vector<int>* parent, int x) {
  std::vector<int>& p = *parent;
  while (p[x] != x) {
    p[x] = p[p[x]];
    x = p[x];
  }
  return x;
}

}  // namespace

double SignedVolume(const TriangleMesh& mesh) {
  // Sum of tetrahedra (centroid, triangle); the centroid keeps it precise far
  // from the origin.
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& v : mesh.vertices) c += v.cast<double>();
  if (!mesh.vertices.empty()) c /= static_cast<double>(mesh.vertices.size());
  double six_volume = 0;
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d a = mesh.vertices[f[0]].cast<double>() - c;
    const Eigen::Vector3d b = mesh.vertices[f[1]].cast<double>() - c;
    const Eigen::Vector3d d = mesh.vertices[f[2]].cast<double>() - c;
    six_volume += a.dot(b.cross(d));
  }
  return six_volume / 6.0;
}

bool OrientOutwards(TriangleMesh* mesh) {
  if (SignedVolume(*mesh) >= 0) return false;
  for (auto& f : mesh->faces) std::swap(f[1], f[2]);
  for (auto& n : mesh->vertex_normals) n = -n;
  return true;
}

int KeepLargestComponent(TriangleMesh* mesh) {
  std::vector<int> parent(mesh->vertices.size());
  std::iota(parent.begin(), parent.end(), 0);
  for (const auto& f : mesh->faces) {
    for (int k = 1; k < 3; ++k) {
      const int a = FindRoot(&parent, f[0]), b = FindRoot(&parent, f[k]);
      if (a != b) parent[a] = b;
    }
  }
  std::unordered_map<int, int> faces_of_root;
  for (const auto& f : mesh->faces) ++faces_of_root[FindRoot(&parent, f[0])];
  if (faces_of_root.size() <= 1) return 0;
  int best_root = -1, best_count = -1;
  for (const auto& [root, count] : faces_of_root) {
    if (count > best_count) {
      best_root = root;
      best_count = count;
    }
  }
  TriangleMesh kept;
  std::vector<int> index_of(mesh->vertices.size(), -1);
  const bool normals = mesh->vertex_normals.size() == mesh->vertices.size();
  for (const auto& f : mesh->faces) {
    if (FindRoot(&parent, f[0]) != best_root) continue;
    Eigen::Vector3i face;
    for (int k = 0; k < 3; ++k) {
      int& index = index_of[f[k]];
      if (index < 0) {
        index = static_cast<int>(kept.vertices.size());
        kept.vertices.push_back(mesh->vertices[f[k]]);
        if (normals) kept.vertex_normals.push_back(mesh->vertex_normals[f[k]]);
      }
      face[k] = index;
    }
    kept.faces.push_back(face);
  }
  const int dropped = static_cast<int>(mesh->faces.size() - kept.faces.size());
  *mesh = std::move(kept);
  return dropped;
}

MeshSummary SummarizeMesh(const TriangleMesh& mesh) {
  MeshSummary s;
  s.num_vertices = static_cast<int>(mesh.vertices.size());
  s.num_faces = static_cast<int>(mesh.faces.size());
  Eigen::Vector3f lo, hi;
  mesh.Bounds(&lo, &hi);
  s.min = lo.cast<double>();
  s.max = hi.cast<double>();
  s.surface_area = mesh.SurfaceArea();
  s.signed_volume = SignedVolume(mesh);
  s.closed = mesh.IsClosed();
  std::unordered_map<uint64_t, int> edge_count;
  edge_count.reserve(mesh.faces.size() * 3);
  std::vector<int> parent(mesh.vertices.size());
  std::iota(parent.begin(), parent.end(), 0);
  for (const auto& f : mesh.faces) {
    for (int k = 0; k < 3; ++k) {
      uint32_t a = static_cast<uint32_t>(f[k]), b = static_cast<uint32_t>(f[(k + 1) % 3]);
      if (a > b) std::swap(a, b);
      ++edge_count[(static_cast<uint64_t>(a) << 32) | b];
      const int ra = FindRoot(&parent, f[k]), rb = FindRoot(&parent, f[(k + 1) % 3]);
      if (ra != rb) parent[ra] = rb;
    }
  }
  for (const auto& [edge, count] : edge_count) {
    if (count == 1) ++s.boundary_edges;
    if (count > 2) ++s.non_manifold_edges;
  }
  std::vector<char> used(mesh.vertices.size(), 0);
  for (const auto& f : mesh.faces) used[f[0]] = used[f[1]] = used[f[2]] = 1;
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    if (used[v] && FindRoot(&parent, static_cast<int>(v)) == static_cast<int>(v)) ++s.num_components;
  }
  return s;
}

}  // namespace arpos
