#pragma once
/// Building and conditioning point clouds: depth back-projection, voxel
/// downsampling, normals and GICP covariances, cropping and segmentation
/// helpers.
///
/// Frames: DepthToCloud returns points in the camera frame (OpenCV: x right,
/// y down, z forward); every other function keeps the frame of its input.
/// Units: metres. Functions with a `num_threads` option use OpenMP
/// (0 = OpenMP's default); their results do not depend on the thread count.
/// All functions are re-entrant; none keeps state between calls.

#include <Eigen/Core>
#include <cstdint>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "geometry/rigid3.h"
#include "registration/kdtree.h"
#include "registration/point_cloud.h"
#include "sensor/intrinsics.h"
#include "sensor/rgbd_frame.h"

namespace arpos {

struct DepthCloudOptions {
  int stride_px = 1;          ///< use every stride-th pixel in u and v
  double min_depth_m = 0.15;  ///< camera z below this is dropped
  double max_depth_m = 4.0;   ///< camera z above this is dropped
  /// Undistort rays when the intrinsics have distortion (OpenCV model); the
  /// per-pixel rays are computed once per call.
  bool undistort = true;
  std::string Validate() const;  ///< empty if valid, else "field: problem"
};

/// Back-projects a depth image into the camera frame. `depth` is CV_16UC1
/// (value / depth_units_per_m metres, 0 = no reading) or CV_32FC1 (same rule;
/// pass 1 for metres; 0 or NaN = no reading). `mask` is empty or CV_8UC1 of
/// the depth's size; only pixels where it is nonzero are used. The points come
/// in row-major pixel order. Throws arpos::Error for mismatched sizes or types
/// or invalid options.
PointCloud DepthToCloud(const cv::Mat& depth, double depth_units_per_m,
                        const CameraIntrinsics& intrinsics, const DepthCloudOptions& options = {},
                        const cv::Mat& mask = cv::Mat());
/// Same for a frame (uses frame.depth and frame.depth_scale).
PointCloud DepthToCloud(const RgbdFrame& frame, const CameraIntrinsics& intrinsics,
                        const DepthCloudOptions& options = {}, const cv::Mat& mask = cv::Mat());

/// One point per occupied voxel of side `voxel_m` (cells aligned at the
/// frame origin): the centroid of the voxel's points; normals, if present,
/// are averaged and renormalised; covariances are dropped (recompute them).
/// Output order is by voxel key, so the result is deterministic.
/// voxel_m <= 0 returns a copy. Throws arpos::Error if a point lies more than
/// about a million voxels from the origin (the key would overflow).
PointCloud VoxelDownsample(const PointCloud& cloud, double voxel_m);

struct NormalOptions {
  int k = 20;  ///< neighbours for the local PCA (>= 3; the point itself counts)
  /// Normals point towards this point (the sensor; origin in the camera
  /// frame) unless the cloud already has normals and orient_like_existing is
  /// set, in which case each new normal takes the sign of the old one.
  Eigen::Vector3d viewpoint = Eigen::Vector3d::Zero();
  bool orient_like_existing = true;
  /// GICP covariance regularisation: eigenvalues replaced by (eps, 1, 1),
  /// eps along the normal (small_gicp's plane model).
  double covariance_epsilon = 1e-3;
  int num_threads = 0;
  std::string Validate() const;
};

/// k-NN PCA normals (smallest eigenvector of the neighbourhood covariance).
/// `tree` must have been built over `cloud`. Points with fewer than 3
/// neighbours get the unit vector towards the viewpoint.
void EstimateNormals(PointCloud* cloud, const KdTree& tree, const NormalOptions& options = {});
/// GICP covariances (regularised as NormalOptions::covariance_epsilon says),
/// from the same k-NN as the normals.
void EstimateCovariances(PointCloud* cloud, const KdTree& tree,
                         const NormalOptions& options = {});
/// Both from one neighbour search per point (the fused pass GICP targets
/// use).
void EstimateNormalsAndCovariances(PointCloud* cloud, const KdTree& tree,
                                   const NormalOptions& options = {});

/// A box with its own frame: centre at the origin of `frame_from_box`, edges
/// along its axes, extending +-half_extents_m.
struct OrientedBox {
  Rigid3d frame_from_box;
  Eigen::Vector3d half_extents_m = Eigen::Vector3d::Zero();
  bool Contains(const Eigen::Vector3d& point_in_frame) const;
};

/// Points inside `box` (given in the cloud's frame), attributes kept.
PointCloud CropToBox(const PointCloud& cloud, const OrientedBox& box);

/// A plane n.p + d = 0 with unit n; SignedDistance > 0 on the side n points to.
struct Plane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double offset_m = 0;  ///< d
  double SignedDistance(const Eigen::Vector3d& p) const { return normal.dot(p) + offset_m; }
};

/// Points whose signed distance from `plane` exceeds `min_height_m`, e.g. the
/// body above the couch top (pass a couple of centimetres to drop the couch
/// surface and its noise).
PointCloud KeepAbovePlane(const PointCloud& cloud, const Plane& plane, double min_height_m);

struct PlaneFitOptions {
  double distance_threshold_m = 0.005;
  int iterations = 500;
  uint64_t seed = 1;
  /// If set, only planes whose normal is within max_angle_rad of this
  /// direction (either sign) are accepted, and the result's normal is
  /// flipped to agree with it.
  std::optional<Eigen::Vector3d> expected_normal;
  double max_angle_rad = 0.35;
  std::string Validate() const;
};

struct PlaneFitResult {
  Plane plane;
  int num_inliers = 0;
};

/// RANSAC plane fit with a least-squares refit on the inliers; nullopt if the
/// cloud has fewer than 3 points or no plane passes the normal constraint.
/// Deterministic for a given seed.
std::optional<PlaneFitResult> FitPlaneRansac(const PointCloud& cloud,
                                             const PlaneFitOptions& options = {});

/// Euclidean clustering (points closer than `tolerance_m` are connected):
/// labels per point, clusters numbered by decreasing size from 0.
std::vector<int> EuclideanClusterLabels(const PointCloud& cloud, double tolerance_m,
                                        int* num_clusters = nullptr);
/// The largest Euclidean cluster (attributes kept); empty for an empty cloud.
PointCloud LargestCluster(const PointCloud& cloud, double tolerance_m);

}  // namespace arpos
