#pragma once
/// Between triangle meshes and point clouds: surface sampling (a reference
/// model as a registration cloud) and exact point-to-surface distances (for
/// evaluation against a true surface and for pruning).
///
/// Frames: everything stays in the mesh's frame. Units: metres.

#include <cstdint>
#include <vector>

#include "geometry/triangle_mesh.h"
#include "registration/kdtree.h"
#include "registration/point_cloud.h"

namespace arpos {

/// Area-uniform random samples of the mesh surface with the face normals
/// (counter-clockwise faces: outward). About area / spacing_m^2 points
/// (`spacing_m` > 0). Deterministic for a given seed. Degenerate faces are
/// skipped.
PointCloud SampleMeshSurface(const TriangleMesh& mesh, double spacing_m, uint64_t seed = 1);

/// Exact unsigned distance from points to a triangle mesh's surface.
/// Thread-safety: construction single-threaded; Distance() is const and may be
/// called concurrently.
class MeshDistance {
 public:
  explicit MeshDistance(const TriangleMesh& mesh);
  /// Distance from `point` to the closest point of any face; +infinity for a
  /// mesh without faces. If `closest` is given it receives that point.
  double Distance(const Eigen::Vector3d& point, Eigen::Vector3d* closest = nullptr) const;
  /// Distances of every point of `cloud` (OpenMP, 0 threads = default).
  std::vector<double> Distances(const PointCloud& cloud, int num_threads = 0) const;

 private:
  std::vector<Eigen::Vector3d> a_, b_, c_;  ///< triangle corners
  KdTree centroid_tree_;
  double max_radius_m_ = 0;  ///< largest centroid-to-corner distance
};

/// Closest point to `p` on triangle (a, b, c) (Ericson, Real-Time Collision
/// Detection 5.1.5); works for degenerate triangles too.
Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c);

/// Summary of a distance sample (metres). Empty input gives zeros.
struct DistanceStats {
  double mean_m = 0;
  double rms_m = 0;
  double median_m = 0;
  double p95_m = 0;
  double max_m = 0;
  size_t count = 0;
};
DistanceStats SummariseDistances(std::vector<double> distances_m);

}  // namespace arpos
