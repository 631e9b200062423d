#pragma once
/// Indexed triangle mesh in metres, in whatever frame its name says
/// (e.g. `model` for a reference model). Faces are counter-clockwise seen
/// from outside (normals point out of the body).

#include <Eigen/Core>
#include <vector>

#include "geometry/rigid3.h"

namespace arpos {

struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Eigen::Vector3i> faces;
  std::vector<Eigen::Vector3f> vertex_normals;  ///< optional: empty or one per vertex

  bool empty() const { return faces.empty(); }
  /// Area-weighted vertex normals from the faces.
  void ComputeVertexNormals();
  /// Axis-aligned bounds; zero vectors for an empty mesh.
  void Bounds(Eigen::Vector3f* min, Eigen::Vector3f* max) const;
  /// Applies b_from_a to vertices (and rotates normals).
  void Transform(const Rigid3d& b_from_a);
  double SurfaceArea() const;
  /// True if every edge is shared by exactly two faces.
  bool IsClosed() const;
};

}  // namespace arpos
