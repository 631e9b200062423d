#pragma once
/// Pose of one square marker from its four corners, optionally with depth.
///
/// A small planar square seen by one camera has two poses that explain its
/// corners almost equally well (IPPE's two solutions: the marker tilted
/// "towards" or "away" about the line of sight). For a 3 cm marker at 0.8 m
/// the wrong one often wins on reprojection error alone. A registered depth
/// image decides: the marker lies on a surface whose normal and distance the
/// depth pixels inside the marker measure directly.
///
/// Frames: `camera_from_marker` maps marker-frame points (OpenCV ArUco: origin
/// at the marker centre, x right, y up, z out of the printed face, metres) to
/// the OpenCV camera frame (x right, y down, z forward). Corner k of the
/// marker is MarkerCornersInMarker(size)[k], in MarkerObservation order.
///
/// Lens distortion: corners (and depth pixels) are undistorted with the
/// intrinsics first; reprojection errors are measured in undistorted pixels.

#include <Eigen/Core>
#include <array>
#include <limits>
#include <string>

#include <opencv2/core.hpp>

#include "features/marker_observation.h"
#include "geometry/rigid3.h"
#include "sensor/intrinsics.h"

namespace arpos {

struct MarkerPoseOptions {
  /// Depth is sampled inside the corner quadrilateral shrunk about its centre
  /// by this factor (keeps away from the marker's edges, where depth sensors
  /// smear).
  double depth_region_scale = 0.8;
  int min_depth_points = 12;
  /// Depth plane fits worse than this RMS (m) are not used.
  double max_depth_plane_rms_m = 0.006;
  /// An IPPE solution agrees with depth if its z axis is within this angle of
  /// the depth plane normal and its centre within this distance of the plane.
  double max_depth_normal_error_deg = 20.0;
  double max_depth_distance_error_m = 0.02;
  /// Without depth, a solution is unambiguous when the other one's
  /// reprojection RMS is at least this many times larger.
  double min_unambiguous_ratio = 4.0;

  /// Joint refinement of the depth-selected pose with corners and depth.
  bool refine_with_depth = true;
  /// Corner noise (px, 1 sigma) weighting the corner residuals; the
  /// observation's own corner_sigma_px is used when larger.
  double corner_sigma_px = 0.05;
  /// Per-pixel depth noise (m, 1 sigma) weighting the depth residuals.
  double depth_sigma_m = 0.0015;
  /// Depth errors are partly systematic (sensor bias, colour-depth
  /// registration), so N depth pixels are weighted as at most this many
  /// independent ones.
  int depth_max_effective_points = 30;
  int max_refine_iterations = 10;

  std::string Validate() const;
  bool Check(std::string* reason = nullptr) const;
};

enum class MarkerPoseStatus {
  kOk = 0,         ///< unambiguous by reprojection, or chosen by agreeing depth
  kAmbiguous,      ///< no usable depth and the two solutions reproject alike
  kDepthMismatch,  ///< depth usable but neither solution agrees with it
  kFailed,         ///< degenerate corners, PnP failure
};

const char* MarkerPoseStatusName(MarkerPoseStatus status);

/// Robust plane through the depth pixels inside a marker.
struct DepthPlane {
  bool valid = false;
  Eigen::Vector3d normal_in_camera = Eigen::Vector3d::Zero();  ///< unit, towards the camera
  Eigen::Vector3d point_in_camera = Eigen::Vector3d::Zero();   ///< centroid of the inliers
  double rms_m = 0;                                            ///< inlier distances to the plane
  int num_points = 0;                                          ///< valid depth pixels in the region
  int num_inliers = 0;
  /// Signed distance of a camera-frame point from the plane (positive towards the camera).
  double SignedDistanceM(const Eigen::Vector3d& point_in_camera_frame) const {
    return normal_in_camera.dot(point_in_camera_frame - point_in_camera);
  }
};

struct IppeSolution {
  Rigid3d camera_from_marker;
  double reprojection_rms_px = 0;  ///< sqrt(mean over the 4 corners of |error|^2)
  /// Agreement with the depth plane (NaN without a valid plane): angle
  /// between the marker's z axis and the plane normal; signed distance of the
  /// marker centre from the plane (positive: in front of it).
  double depth_normal_error_deg = std::numeric_limits<double>::quiet_NaN();
  double depth_distance_error_mm = std::numeric_limits<double>::quiet_NaN();
};

struct MarkerPose {
  MarkerPoseStatus status = MarkerPoseStatus::kFailed;
  Rigid3d camera_from_marker;
  double reprojection_rms_px = 0;
  /// reprojection RMS of the worse IPPE solution over the better one's (>= 1);
  /// large means unambiguous. Infinity for exact corners.
  double ambiguity_ratio = 0;
  std::array<IppeSolution, 2> solutions{};  ///< IPPE solutions, best reprojection first
  int num_solutions = 0;
  int chosen = 0;                ///< index of the solution the pose started from
  bool chosen_by_depth = false;  ///< depth overrode or confirmed the choice
  bool refined_with_depth = false;
  DepthPlane depth_plane;
  /// Agreement of the final pose with the depth plane (NaN without depth).
  double depth_normal_error_deg = std::numeric_limits<double>::quiet_NaN();
  double depth_distance_error_mm = std::numeric_limits<double>::quiet_NaN();
  std::string message;  ///< why, for kFailed / kDepthMismatch
};

/// The marker's corners in its own frame, in MarkerObservation order.
std::array<Eigen::Vector3d, 4> MarkerCornersInMarker(double marker_size_m);

/// Plane fit to the depth pixels inside the quadrilateral `corners_px`
/// (shrunk by options.depth_region_scale). `depth` is registered to the colour
/// image: CV_16UC1 in units of intrinsics.depth_scale per metre, or CV_32FC1
/// in metres; 0 or non-finite = no reading. Iteratively reweighted (Tukey).
DepthPlane FitDepthPlaneInQuad(const cv::Mat& depth,
                               const std::array<Eigen::Vector2d, 4>& corners_px,
                               const CameraIntrinsics& intrinsics,
                               const MarkerPoseOptions& options = {});

/// Both IPPE solutions (cv::solvePnPGeneric, SOLVEPNP_IPPE_SQUARE), the
/// ambiguity ratio, and, with a non-empty `depth`, the depth-based choice and
/// a joint corner + depth refinement (Gauss-Newton; see MarkerPoseOptions).
/// Expected failures come back as status; throws arpos::Error for invalid
/// arguments (size <= 0, invalid intrinsics, depth of the wrong type/size).
MarkerPose EstimateMarkerPose(const MarkerObservation& observation, double marker_size_m,
                              const CameraIntrinsics& intrinsics, const cv::Mat& depth = cv::Mat(),
                              const MarkerPoseOptions& options = {});

}  // namespace arpos
