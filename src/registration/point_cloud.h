#pragma once
/// Point clouds for registration and reconstruction.
///
/// A PointCloud lives in one frame, which its variable name says
/// (`cloud_in_camera`, `model_cloud`, `reconstruction_in_room`). Points are
/// homogeneous (x, y, z, 1) in metres, normals (nx, ny, nz, 0) of unit length,
/// covariances 4x4 with a zero last row and column (the 3x3 block in m^2, or
/// normalised as GICP uses them). The homogeneous layout lets Eigen vectorise
/// the hot loops (the small_gicp layout) and makes `T * p` one 4x4 product.
///
/// `normals` and `covs` are optional: each is either empty or has one entry
/// per point. Algorithms reach the data only through the `traits` functions
/// below, so a hot path can run on any type that provides the same functions.
///
/// Thread-safety: a const PointCloud may be read from any number of threads.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <vector>

#include "geometry/rigid3.h"

namespace arpos {

struct PointCloud {
  std::vector<Eigen::Vector4d> points;   ///< (x, y, z, 1), metres
  std::vector<Eigen::Vector4d> normals;  ///< optional: (nx, ny, nz, 0), unit
  std::vector<Eigen::Matrix4d> covs;     ///< optional: 3x3 block used, rest zero

  PointCloud() = default;
  /// From plain 3-D points (no normals, no covariances).
  explicit PointCloud(const std::vector<Eigen::Vector3d>& points_m);

  size_t size() const { return points.size(); }
  bool empty() const { return points.empty(); }
  bool has_normals() const { return !points.empty() && normals.size() == points.size(); }
  bool has_covs() const { return !points.empty() && covs.size() == points.size(); }

  /// Appends a point (and a normal when `normal` is given and the cloud keeps
  /// normals or is empty). Drops covariances (they are per-neighbourhood).
  void Add(const Eigen::Vector3d& point_m);
  void Add(const Eigen::Vector3d& point_m, const Eigen::Vector3d& normal);
  /// Appends all of `other` (attributes kept only if both have them).
  void Append(const PointCloud& other);

  Eigen::Vector3d point3(size_t i) const { return points[i].head<3>(); }
  Eigen::Vector3d normal3(size_t i) const { return normals[i].head<3>(); }

  /// Applies b_from_a to points, normals and covariances (R C R^T) in place;
  /// the cloud is then in frame b.
  void Transform(const Rigid3d& b_from_a);
  /// A copy in frame b.
  PointCloud Transformed(const Rigid3d& b_from_a) const;

  /// Axis-aligned bounds; an empty box for an empty cloud.
  Eigen::AlignedBox3d Bounds() const;
  Eigen::Vector3d Centroid() const;  ///< zero for an empty cloud

  /// The points with indices `indices` (attributes kept), in that order.
  PointCloud Select(const std::vector<size_t>& indices) const;
  /// Points as plain 3-D vectors (for other layers and tests).
  std::vector<Eigen::Vector3d> Points3d() const;
  /// Throws arpos::Error if the attribute sizes do not match the points or a
  /// point has w != 1 (a broken invariant, not bad input).
  void CheckInvariants() const;
};

/// Trait access (small_gicp style): generic hot-path code calls these, never
/// the members, so the same algorithm can run on other cloud types that
/// define the same free functions in their namespace.
namespace traits {
inline size_t size(const PointCloud& cloud) { return cloud.points.size(); }
inline bool has_normals(const PointCloud& cloud) { return cloud.has_normals(); }
inline bool has_covs(const PointCloud& cloud) { return cloud.has_covs(); }
inline const Eigen::Vector4d& point(const PointCloud& cloud, size_t i) { return cloud.points[i]; }
inline const Eigen::Vector4d& normal(const PointCloud& cloud, size_t i) {
  return cloud.normals[i];
}
inline const Eigen::Matrix4d& cov(const PointCloud& cloud, size_t i) { return cloud.covs[i]; }
}  // namespace traits

}  // namespace arpos
