#pragma once
/// Bundle adjustment of the room map (Ceres): camera poses, marker poses and
/// keypoint landmarks, jointly, over
/// - marker corner reprojections (each corner: the marker's pose and its
///   printed side give its room position),
/// - keypoint reprojections,
/// - keypoint depths (measured z vs the landmark's z in the camera), and
/// - marker-plane depths (depth pixels inside a marker vs the depth of its
///   plane along the pixel's ray),
/// - room-plane depths (depth pixels on a plane of the room, the floor or a
///   wall, vs that plane along the pixel's ray; the plane is adjusted too),
/// each whitened by its sigma and under a Huber loss. The origin marker's pose
/// is held at the identity: it fixes the room frame (and, with the printed
/// marker side and depth, the scale).
///
/// Frames: camera_from_room per frame, room_from_marker per marker, landmark
/// positions in the room frame, metres. Pixels are undistorted (ideal) pixels
/// of `intrinsics`.

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "geometry/rigid3.h"
#include "sensor/intrinsics.h"

namespace arpos {

/// A depth pixel inside a marker: ideal pixel and measured z (m).
struct DepthSample {
  Eigen::Vector2f pixel;
  float depth_m = 0;
};

/// Depth pixels on a grid inside a marker (marker coordinates within +-0.35
/// of the side: away from the edges, where depth smears), at most
/// `max_samples`, with their ideal (undistorted) pixels. `depth` CV_16UC1 in
/// units of intrinsics.depth_scale per metre; corners in image pixels.
std::vector<DepthSample> SampleMarkerDepth(const cv::Mat& depth,
                                           const std::array<Eigen::Vector2d, 4>& corners_image_px,
                                           const CameraIntrinsics& intrinsics, int max_samples);

/// Depth pixels on the plane a marker lies on, around it: a grid over the
/// square of half-width `half_width_m` (metres, marker plane) about the
/// marker's centre, mapped through the homography of its corners (side
/// `marker_side_m`), at most `max_samples`, ideal pixels. For the support
/// plane (floor or wall) of the origin marker: its depth fixes the plane's
/// tilt far better than the marker's own few pixels.
std::vector<DepthSample> SampleSupportDepth(const cv::Mat& depth,
                                            const std::array<Eigen::Vector2d, 4>& corners_image_px,
                                            const CameraIntrinsics& intrinsics, double marker_side_m,
                                            double half_width_m, int max_samples);

struct BaMarkerObservation {
  int camera = -1;  ///< index into BaProblem::camera_from_room
  int marker = -1;  ///< index into BaProblem::room_from_marker
  std::array<Eigen::Vector2d, 4> corners_px{};
  std::array<double, 4> sigma_px{{1, 1, 1, 1}};
  std::vector<DepthSample> depth_samples;
};

struct BaKeypointObservation {
  int camera = -1;
  int landmark = -1;
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
  double sigma_px = 1;
  float depth_m = 0;  ///< 0 = no depth
};

/// A plane of the room (n . x = offset, room frame, n unit), adjusted.
/// `markers` (indices into BaProblem::room_from_marker: markers printed flat
/// on that floor or wall) lie on it: their centres within flatness_sigma_m,
/// their normals along the plane's within tilt_sigma_rad (0: not tied).
struct BaPlane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double offset = 0;
  std::vector<int> markers;
  double flatness_sigma_m = 0.002;
  double tilt_sigma_rad = 0;
};

/// Depth pixels of one camera on one room plane. Each sample's sigma is the
/// depth noise model's times `share` (>= 1: the samples of one view share
/// its depth errors and count as fewer independent ones).
struct BaPlaneObservation {
  int camera = -1;
  int plane = -1;
  double share = 1;
  std::vector<DepthSample> samples;
};

struct BaProblem {
  CameraIntrinsics intrinsics;
  double marker_size_m = 0;
  std::vector<Rigid3d> camera_from_room;
  std::vector<Rigid3d> room_from_marker;
  std::vector<bool> marker_fixed;  ///< parallel to room_from_marker (the origin: true)
  std::vector<Eigen::Vector3d> landmarks_in_room;
  std::vector<BaMarkerObservation> marker_observations;
  std::vector<BaKeypointObservation> keypoint_observations;
  std::vector<BaPlane> planes;
  std::vector<BaPlaneObservation> plane_observations;
};

struct BaOptions {
  /// Huber threshold on whitened residuals (residual / sigma).
  double huber = 2.0;
  /// sigma(z) = depth_sigma_const_m + depth_sigma_quad_per_m * z^2.
  double depth_sigma_const_m = 0.001;
  double depth_sigma_quad_per_m = 0.0015;
  /// Depth noise is partly correlated (sensor bias, smooth error fields): the
  /// samples of one marker view count as at most this many independent ones.
  int marker_depth_max_effective = 4;
  bool use_keypoint_depth = true;
  bool use_marker_depth = true;
  bool use_plane_depth = true;
  int max_iterations = 50;
  int threads = 2;
  double function_tolerance = 1e-7;
  /// After the solve, the covariance of each of these markers' centre
  /// relative to marker `covariance_reference` (indices into
  /// room_from_marker): BaSummary::relative_centre_covariance. Empty: none.
  std::vector<int> covariance_markers;
  int covariance_reference = -1;

  std::string Validate() const;
  bool Check(std::string* reason = nullptr) const;
  double DepthSigmaM(double z_m) const { return depth_sigma_const_m + depth_sigma_quad_per_m * z_m * z_m; }
};

struct BaSummary {
  bool usable = false;  ///< Ceres returned a usable solution
  int iterations = 0;
  double initial_cost = 0, final_cost = 0;
  double seconds = 0;
  std::string message;
  /// Per BaOptions::covariance_markers: the covariance (m^2) of that
  /// marker's centre in the reference marker's frame, marginal over
  /// everything else the adjustment estimates (cameras, landmarks, planes,
  /// the other markers); infinite where it could not be computed.
  std::vector<Eigen::Matrix3d> relative_centre_covariance;
  /// Row for row: the covariance (rad^2) of that marker's orientation
  /// relative to the reference marker's, about the reference's axes.
  std::vector<Eigen::Matrix3d> relative_rotation_covariance;
  double covariance_seconds = 0;
};

/// Optimises `problem` in place. Throws arpos::Error for inconsistent indices.
BaSummary RunBundleAdjustment(BaProblem* problem, const BaOptions& options);

/// Residuals at the current state (pixels / metres, not whitened).
struct BaResiduals {
  /// Per marker observation: RMS over its 4 corners of |reprojection error| (px).
  std::vector<double> marker_rms_px;
  /// Per keypoint observation: |reprojection error| (px); depth error (m, NaN if none).
  std::vector<double> keypoint_px;
  std::vector<double> keypoint_depth_m;
  /// Per marker observation: median over its depth samples of measured /
  /// predicted z (NaN without samples): the scale check, 1.000 if map and depth agree.
  std::vector<double> marker_depth_ratio;
};
BaResiduals ComputeBaResiduals(const BaProblem& problem);

}  // namespace arpos
