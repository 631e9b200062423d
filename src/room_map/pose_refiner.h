#pragma once
/// Non-linear refinement of one camera pose from 2D-3D correspondences
/// (marker corners and keypoints jointly), optional depth measurements and an
/// optional pose prior, with robust losses. Gauss-Newton on SE(3) with a left
/// perturbation camera_from_room <- exp(delta) * camera_from_room; 6x6 normal
/// equations, no allocation per iteration once warmed up: fast enough for
/// every frame (~50 us for 500 correspondences).
///
/// Frames and units: points in the room frame (m); pixels undistorted (ideal)
/// pixels of `intrinsics` (OpenCV convention); depth = z in the camera frame (m).
///
/// Robust losses (on whitened residuals, i.e. residual / sigma):
/// - group kMarker: Huber with threshold `marker_huber`;
/// - group kKeypoint: Huber for the first `huber_iterations`, then Tukey's
///   biweight with cut-off `keypoint_tukey` (outliers get zero weight).
/// A correspondence is an inlier if its whitened reprojection residual is
/// below `inlier_threshold` (and its depth residual, if any, below it too).

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "geometry/rigid3.h"
#include "sensor/depth_timing.h"
#include "sensor/intrinsics.h"

namespace arpos {

enum class CorrespondenceGroup : std::uint8_t { kMarker = 0, kKeypoint = 1 };

/// Correspondences as parallel arrays (structure of arrays for speed).
struct PoseCorrespondences {
  std::vector<Eigen::Vector3d> points_in_room;
  std::vector<Eigen::Vector2d> pixels;
  std::vector<float> inv_sigma_px;       ///< 1 / sigma of the pixel (per axis)
  std::vector<float> depth_m;            ///< measured z, 0 = none
  std::vector<float> inv_sigma_depth;    ///< 1 / sigma(z) of that measurement (1/m)
  std::vector<CorrespondenceGroup> group;
  std::vector<int> tag;                  ///< caller's id (landmark index, marker id * 4 + corner)

  /// Depth pixels on known planes (e.g. inside a mapped marker): the ray of
  /// ideal pixel (x, y, 1) = ((u - cx) / fx, (v - cy) / fy, 1) meets the plane
  /// (point, unit normal, room frame) at a z that should equal the measured
  /// depth. Residual (z_pred - z_meas) * inv_sigma, Huber-weighted.
  std::vector<Eigen::Vector3d> plane_point_in_room;
  std::vector<Eigen::Vector3d> plane_normal_in_room;
  std::vector<Eigen::Vector2d> plane_ray;   ///< (x, y) of the ray (x, y, 1)
  std::vector<float> plane_depth_m;
  std::vector<float> plane_inv_sigma;

  /// Depth of another instant than the colour (sensor/depth_timing.h): the
  /// covariance of the camera's unknown motion between them, on the left
  /// perturbation [rotation; translation] of camera_from_room, shared by
  /// every depth reading above (point depths and plane depths alike), which
  /// the refinement marginalises out. Zero: depth of the colour's instant.
  Eigen::Matrix<double, 6, 6> depth_motion_covariance = Eigen::Matrix<double, 6, 6>::Zero();

  size_t size() const { return pixels.size(); }
  void clear();
  void AddPlaneDepth(const Eigen::Vector3d& point_in_room, const Eigen::Vector3d& normal_in_room,
                     const Eigen::Vector2d& ray_xy, double depth_m, double sigma_m);
  void reserve(size_t n);
  void Add(const Eigen::Vector3d& point_in_room, const Eigen::Vector2d& pixel, double sigma_px,
           CorrespondenceGroup group, int tag, double depth_m = 0, double sigma_depth_m = 0);
};

struct PoseRefinerOptions {
  int max_iterations = 12;
  int huber_iterations = 3;
  double marker_huber = 3.0;
  double keypoint_tukey = 4.0;
  double inlier_threshold = 3.0;
  /// Stop when the update is below these.
  double min_step_rad = 1e-8;
  double min_step_m = 1e-8;

  std::string Validate() const;
  bool Check(std::string* reason = nullptr) const;
};

/// A Gaussian prior on the pose (e.g. from a motion model) about
/// camera_from_room, on the perturbation [rotation (rad); translation (m)]:
/// either isotropic sigmas or, if `information` is set, a full 6x6 information
/// matrix (inverse covariance) in that order.
struct PosePrior {
  Rigid3d camera_from_room;
  double sigma_rad = 0.05;
  double sigma_m = 0.05;
  std::optional<Eigen::Matrix<double, 6, 6>> information;
};

struct PoseRefinementResult {
  Rigid3d camera_from_room;
  bool converged = false;
  int iterations = 0;
  int num_inliers = 0;
  int marker_inliers = 0;    ///< marker corners among the inliers
  int keypoint_inliers = 0;  ///< keypoints among the inliers
  double marker_rms_px = 0;    ///< RMS over inlier marker corners (0 if none)
  double keypoint_rms_px = 0;  ///< RMS over inlier keypoints (0 if none)
  double rms_px = 0;           ///< RMS over all inliers
  std::vector<std::uint8_t> inlier;  ///< per correspondence
  /// Approximate 6x6 information (J^T W J) of [rotation; translation] at the
  /// solution, for quality checks (e.g. degenerate geometry).
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
  /// The same without the prior's share: what the correspondences alone say.
  Eigen::Matrix<double, 6, 6> data_information = Eigen::Matrix<double, 6, 6>::Zero();
  /// What the marker corners alone say (their pixels, at their weights).
  Eigen::Matrix<double, 6, 6> marker_information = Eigen::Matrix<double, 6, 6>::Zero();
  /// Depth of another instant (PoseCorrespondences::depth_motion_covariance
  /// set): the camera's motion from the colour instant to the depth's as the
  /// depth readings measured it at the solution (sensor/depth_timing.h).
  std::optional<DepthCameraMotion> depth_camera_motion;
};

/// Refines `camera_from_room_initial`. Never throws for bad geometry: with
/// fewer than 3 usable correspondences (and no prior) it returns the initial
/// pose with converged = false.
PoseRefinementResult RefineCameraPose(const PoseCorrespondences& correspondences,
                                      const CameraIntrinsics& intrinsics,
                                      const Rigid3d& camera_from_room_initial,
                                      const PoseRefinerOptions& options = {},
                                      const std::optional<PosePrior>& prior = std::nullopt);

/// Correspondence i's share of the information (J^T W J of its reprojection
/// and depth residuals) at `camera_from_room`, weighted as the refiner's last
/// iterations weigh it: what leaving it out takes from a result's
/// `information` (zero when it carries no weight there).
Eigen::Matrix<double, 6, 6> PointInformation(const PoseCorrespondences& correspondences, size_t i,
                                             const CameraIntrinsics& intrinsics,
                                             const Rigid3d& camera_from_room,
                                             const PoseRefinerOptions& options = {});

}  // namespace arpos
