#pragma once
/// A compact static 3-D kd-tree for nearest-neighbour queries on point clouds.
///
/// The tree copies the points (reordered so each leaf is contiguous) and maps
/// results back to the indices of the cloud it was built from; the cloud may
/// be changed or destroyed afterwards. Splits are at the median of the widest
/// axis; queries prune with the incremental distance to the cell (Arya &
/// Mount), the scheme nanoflann uses. Distances are Euclidean, squared, in
/// m^2. The w component of homogeneous points is ignored.
///
/// Thread-safety: construction is single-threaded; all queries are const and
/// may run concurrently from any number of threads.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "registration/point_cloud.h"

namespace arpos {

struct KdTreeOptions {
  int max_leaf_size = 12;  ///< points per leaf (>= 1)
  std::string Validate() const;
};

class KdTree {
 public:
  KdTree() = default;
  /// Builds over `cloud.points`. Throws arpos::Error for invalid options or a
  /// non-finite point.
  explicit KdTree(const PointCloud& cloud, const KdTreeOptions& options = {});
  explicit KdTree(const std::vector<Eigen::Vector3d>& points_m,
                  const KdTreeOptions& options = {});

  size_t size() const { return points_.size(); }
  bool empty() const { return points_.empty(); }

  /// Nearest point to `query` strictly closer than sqrt(max_sq_dist_m2).
  /// Returns false (outputs untouched) if there is none.
  bool Nearest(const Eigen::Vector4d& query, size_t* index, double* sq_dist_m2,
               double max_sq_dist_m2 = std::numeric_limits<double>::infinity()) const;

  /// Up to `k` nearest points within sqrt(max_sq_dist_m2), closest first;
  /// writes `indices[0..n)` and `sq_dists_m2[0..n)` (arrays of at least k)
  /// and returns n (< k only if the tree is smaller or the bound cuts).
  size_t Knn(const Eigen::Vector4d& query, int k, size_t* indices, double* sq_dists_m2,
             double max_sq_dist_m2 = std::numeric_limits<double>::infinity()) const;

  /// Knn that also copies the neighbours' coordinates into `points[0..n)`
  /// (from the tree's own contiguous copy: cheaper than gathering them from
  /// the cloud afterwards).
  size_t KnnWithPoints(const Eigen::Vector4d& query, int k, size_t* indices,
                       double* sq_dists_m2, Eigen::Vector4d* points) const;

  /// Every point within `radius_m` (inclusive), in no particular order,
  /// appended to `indices` after clearing it.
  void RadiusSearch(const Eigen::Vector4d& query, double radius_m,
                    std::vector<size_t>* indices) const;

  /// Indices of the cloud in leaf order: queries issued in this order touch
  /// memory coherently (faster for whole-cloud neighbourhood passes).
  const std::vector<uint32_t>& leaf_order() const { return indices_; }

  // 3-D conveniences.
  bool Nearest(const Eigen::Vector3d& query, size_t* index, double* sq_dist_m2) const {
    return Nearest(Eigen::Vector4d(query.x(), query.y(), query.z(), 1.0), index, sq_dist_m2);
  }
  std::vector<size_t> Knn(const Eigen::Vector3d& query, int k) const;

 private:
  struct Node {
    // Leaf: [begin, end) into points_; inner: children and split plane.
    uint32_t begin = 0, end = 0;
    uint32_t left = 0, right = 0;
    int axis = -1;  ///< -1 for a leaf
    double split = 0;
  };
  void Build(const KdTreeOptions& options);
  uint32_t BuildNode(uint32_t begin, uint32_t end, int max_leaf);
  template <class Set>
  void Search(const Eigen::Vector4d& query, Set& set) const;
  template <class Set>
  void SearchNode(uint32_t id, const Eigen::Vector4d& query, double mindist, double* dists,
                  Set& set) const;

  std::vector<Eigen::Vector4d> points_;  ///< reordered copy
  std::vector<uint32_t> indices_;        ///< points_[i] is cloud point indices_[i]
  std::vector<Node> nodes_;              ///< nodes_[0] is the root
  Eigen::Vector3d root_min_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d root_max_ = Eigen::Vector3d::Zero();
};

}  // namespace arpos
