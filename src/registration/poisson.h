#pragma once
/// Watertight surface from an oriented point cloud: PCL's Poisson surface
/// reconstruction (Kazhdan et al. 2006), then pruned where the surface is far
/// from any input point (Poisson closes holes and invents surface behind the
/// body; the pruning keeps what the points support). PCL stays in poisson.cc.
///
/// Frames: the mesh is in the cloud's frame. Units: metres. Faces are
/// counter-clockwise seen from the side the normals point to (outside).
/// Thread-safety: re-entrant. Nothing is printed.

#include <string>

#include "geometry/triangle_mesh.h"
#include "registration/point_cloud.h"

namespace arpos {

struct PoissonOptions {
  /// Octree depth: resolution ~ bounding cube / 2^depth (8: ~7 mm for a 1.8 m
  /// body). Time grows ~3-4x per level (PITFALLS.md: 0.46 / 1.5 / 5.2 s for
  /// depth 6 / 7 / 8 on 50k points).
  int depth = 8;
  float point_weight = 4.0f;     ///< interpolation weight of the points
  float samples_per_node = 1.5f; ///< larger for noisier clouds
  /// Faces with a vertex farther than this from every input point are
  /// removed; <= 0 keeps the whole watertight mesh.
  double prune_distance_m = 0.01;
  /// PCL's Poisson scales poorly: on this 2-core machine 2 threads took twice
  /// the CPU time for the same wall time, so 1 is the default.
  /// 0 = OpenMP's default.
  int num_threads = 1;
  std::string Validate() const;
};

struct PoissonResult {
  TriangleMesh mesh;           ///< with vertex normals
  int faces_before_pruning = 0;
  bool closed_before_pruning = false;  ///< every edge shared by two faces
  double poisson_s = 0;        ///< PCL reconstruction wall time
  double prune_s = 0;
  double total_s = 0;
};

/// `cloud` needs normals (throws arpos::Error otherwise, or for invalid
/// options). An empty cloud gives an empty mesh.
PoissonResult PoissonMesh(const PointCloud& cloud, const PoissonOptions& options = {});

}  // namespace arpos
