#include "geometry/triangle_mesh.h"

#include <algorithm>
#include <unordered_map>

namespace arpos {

void TriangleMesh::ComputeVertexNormals() {
  vertex_normals.assign(vertices.size(), Eigen::Vector3f::Zero());
  for (const auto& f : faces) {
    const Eigen::Vector3f n =
        (vertices[f[1]] - vertices[f[0]]).cross(vertices[f[2]] - vertices[f[0]]);
    for (int k = 0; k < 3; ++k) vertex_normals[f[k]] += n;  // |n| = 2 * area
  }
  for (auto& n : vertex_normals) {
    const float norm = n.norm();
    if (norm > 0) n /= norm;
  }
}

void TriangleMesh::Bounds(Eigen::Vector3f* min, Eigen::Vector3f* max) const {
  if (vertices.empty()) {
    min->setZero();
    max->setZero();
    return;
  }
  *min = *max = vertices.front();
  for (const auto& v : vertices) {
    *min = min->cwiseMin(v);
    *max = max->cwiseMax(v);
  }
}

void TriangleMesh::Transform(const Rigid3d& b_from_a) {
  const Eigen::Matrix3f r = b_from_a.RotationMatrix().cast<float>();
  const Eigen::Vector3f t = b_from_a.translation.cast<float>();
  for (auto& v : vertices) v = r * v + t;
  for (auto& n : vertex_normals) n = r * n;
}

double TriangleMesh::SurfaceArea() const {
  double area = 0;
  for (const auto& f : faces) {
    area += 0.5 * (vertices[f[1]] - vertices[f[0]])
                      .cast<double>()
                      .cross((vertices[f[2]] - vertices[f[0]]).cast<double>())
                      .norm();
  }
  return area;
}

bool TriangleMesh::IsClosed() const {
  if (faces.empty()) return false;
  std::unordered_map<uint64_t, int> edge_count;
  edge_count.reserve(faces.size() * 3);
  for (const auto& f : faces) {
    for (int k = 0; k < 3; ++k) {
      uint32_t a = static_cast<uint32_t>(f[k]), b = static_cast<uint32_t>(f[(k + 1) % 3]);
      if (a > b) std::swap(a, b);
      ++edge_count[(static_cast<uint64_t>(a) << 32) | b];
    }
  }
  return std::all_of(edge_count.begin(), edge_count.end(),
                     [](const auto& kv) { return kv.second == 2; });
}

}  // namespace arpos
